"""Physical parameters: name, unit, default, bounds, scale — and a value set."""

from __future__ import annotations

import contextlib
import contextvars
import difflib
import functools
import json
import math
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Literal

import numpy as np

from ..data.output import write_file_atomic
from ..errors import ModelError, ParameterWarning, warn_at_caller
from .units import SI_FACTOR

__all__ = ["Parameter", "ParameterSet", "quiet_design_checks", "without_design_checks"]


@dataclass(frozen=True)
class Parameter:
    """One lumped parameter of the circuit model.

    Attributes
    ----------
    name : str
        Unique name, ``<component>_<symbol>`` (e.g. ``reg_k``).
    unit : str
        Engineering unit the value is given in (a key of ``units.SI_FACTOR``).
    default : float
        Datasheet-like value, in ``unit``. Never fitted.
    lower, upper : float
        Physical bounds, in ``unit``.
    description : str
        What the parameter is.
    transform : {"log", "linear"}
        Space a fitter works in: ``log`` for strictly positive magnitudes,
        ``linear`` for signed quantities or those whose bound includes zero.
    scale : float
        Typical magnitude (in ``unit``) used to scale the decision variable of a
        linear-space fit; defaults to ``max(|lower|, |upper|, |default|)``.
    component : str
        Component or effect that owns the parameter.
    """

    name: str
    unit: str
    default: float
    lower: float
    upper: float
    description: str
    transform: Literal["log", "linear"] = "log"
    scale: float = 0.0
    component: str = ""

    def __post_init__(self) -> None:
        # Bounds written as multiples of a default (0.2 * 12 mm) carry binary noise
        # (2.4000000000000004) that would reject a user's "2.4"; keep 12 digits.
        for name in ("lower", "upper"):
            object.__setattr__(self, name, float(f"{getattr(self, name):.12g}"))
        problems = []
        if self.unit not in SI_FACTOR:
            problems.append(f"unit {self.unit!r} is not a known unit")
        if not (self.lower <= self.default <= self.upper):
            problems.append(f"default {self.default} outside bounds [{self.lower}, {self.upper}]")
        if self.transform == "log" and self.lower <= 0:
            problems.append("log transform needs a strictly positive lower bound")
        if self.transform not in ("log", "linear"):
            problems.append(f"transform {self.transform!r} is not 'log' or 'linear'")
        if problems:
            raise ModelError(f"parameter {self.name!r}: " + "; ".join(problems))
        if self.scale == 0.0:
            mag = max(abs(self.lower), abs(self.upper), abs(self.default))
            object.__setattr__(self, "scale", mag if mag > 0 else 1.0)

    @property
    def si_factor(self) -> float:
        """Factor from ``unit`` to SI."""
        return SI_FACTOR[self.unit]

    def check(self, value: float) -> str | None:
        """Return a problem description when ``value`` is not finite or out of bounds."""
        if not math.isfinite(value):
            return f"{self.name} = {value} is not finite"
        if value < self.lower or value > self.upper:
            return (
                f"{self.name} = {value} {self.unit} outside bounds "
                f"[{self.lower}, {self.upper}] {self.unit}"
            )
        return None

    def to_dict(self) -> dict:
        """Plain-JSON description (for reports and FMU model descriptions)."""
        return {
            "name": self.name,
            "unit": self.unit,
            "default": self.default,
            "lower": self.lower,
            "upper": self.upper,
            "transform": self.transform,
            "scale": self.scale,
            "component": self.component,
            "description": self.description,
        }


@dataclass(frozen=True)
class ParameterSet(Mapping[str, float]):
    """Values for the parameters of one model, in engineering units.

    A mapping ``name -> value``; immutable: :meth:`replace` returns a new set.
    Values are checked against the parameters' bounds.

    Parameters
    ----------
    parameters : tuple of Parameter
        The model's parameters, in model order.
    values : dict, optional
        Overrides of the defaults, ``name -> value`` in each parameter's unit.

    Attributes
    ----------
    values : mapping
        Every parameter's value (engineering units), read-only
        (:class:`types.MappingProxyType`): a value is changed with :meth:`replace`,
        which checks its bounds.

    Warns
    -----
    ParameterWarning
        Once per Python process, for values within their bounds that leave a component
        unable to do its job: a latch valve that cannot latch (latch-off pressure not below
        latch-on, e.g. ``latch_d2 ≤ latch_d1``;
        :func:`~clutchlab.physics.components.latch_snap_problem`). The set is accepted (a
        design sweep may mean it); :meth:`from_vector` does not warn.
    """

    parameters: tuple[Parameter, ...]
    values: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        known = {p.name: p for p in self.parameters}
        unknown = sorted(set(self.values) - set(known))
        problems = [_unknown(n, known) for n in unknown]
        full = {}
        for p in self.parameters:
            raw = self.values.get(p.name, p.default)
            try:
                if isinstance(raw, bool):  # float(True) is 1.0: a flag is not a value
                    raise TypeError
                v = float(raw)
            except (TypeError, ValueError):
                problems.append(
                    f"{p.name} = {raw!r} is not a number (give the value in {p.unit}, "
                    "without its unit)"
                )
                continue
            msg = p.check(v)
            if msg:
                problems.append(msg)
            full[p.name] = v
        if problems:
            raise ModelError("invalid parameter values:\n  - " + "\n  - ".join(problems))
        object.__setattr__(self, "values", MappingProxyType(full))
        if _DESIGN_CHECKS.get():
            _warn_design(full)

    def __reduce__(self):
        # a mappingproxy does not pickle (nor deep-copy): rebuild from a plain dict, which
        # also checks the values again
        return (type(self), (self.parameters, dict(self.values)))

    def __repr__(self) -> str:
        # the dataclass repr printed every Parameter with bounds and description (~9000
        # characters for the base circuit): name the count and what differs from the defaults
        changed = self.changed()
        if not changed:
            return f"ParameterSet({len(self)} parameters, all at their datasheet defaults)"
        units = {p.name: p.unit for p in self.parameters}
        shown = [f"{n}={v:.6g} {units[n]}" for n, v in list(changed.items())[:_REPR_CHANGED]]
        if len(changed) > _REPR_CHANGED:
            shown.append(f"… {len(changed) - _REPR_CHANGED} more (see .changed())")
        return f"ParameterSet({len(self)} parameters; changed: {', '.join(shown)})"

    def __getitem__(self, name: str) -> float:
        try:
            return self.values[name]
        except KeyError:
            raise KeyError(f"unknown parameter {name!r}") from None

    def __iter__(self) -> Iterator[str]:
        return iter(p.name for p in self.parameters)

    def __len__(self) -> int:
        return len(self.parameters)

    def spec(self, name: str) -> Parameter:
        """The :class:`Parameter` called ``name``."""
        for p in self.parameters:
            if p.name == name:
                return p
        raise KeyError(f"unknown parameter {name!r}")

    def replace(self, **values: float) -> ParameterSet:
        """A new set with some values changed (engineering units)."""
        return ParameterSet(self.parameters, {**self.values, **values})

    def vector(self) -> np.ndarray:
        """Values in model order, engineering units (what the CasADi functions take)."""
        return np.array([self.values[p.name] for p in self.parameters], dtype=float)

    @classmethod
    def from_vector(cls, parameters: Iterable[Parameter], vector) -> ParameterSet:
        """Inverse of :meth:`vector` (checks the bounds; gives no :class:`ParameterWarning`:
        fitters call it at every iterate)."""
        parameters = tuple(parameters)
        vec = np.asarray(vector, dtype=float).ravel()
        if vec.size != len(parameters):
            raise ModelError(f"expected {len(parameters)} values, got {vec.size}")
        with without_design_checks():
            return cls(parameters, {p.name: float(v) for p, v in zip(parameters, vec, strict=True)})

    def changed(self) -> dict[str, float]:
        """Values that differ from the defaults."""
        return {
            p.name: self.values[p.name] for p in self.parameters if self.values[p.name] != p.default
        }

    def to_json(self, path: str | Path | None = None) -> str:
        """JSON text ``{"parameters": {name: {"value", "unit"}}}``; written to ``path`` if given."""
        doc = {
            "parameters": {
                p.name: {"value": self.values[p.name], "unit": p.unit} for p in self.parameters
            }
        }
        text = json.dumps(doc, indent=2, ensure_ascii=False)
        if path is not None:
            write_file_atomic(path, (text + "\n").encode("utf-8"), overwrite=True)
        return text

    def for_model(
        self, parameters: Iterable[Parameter], model_name: str = "the model"
    ) -> ParameterSet:
        """This set, checked to belong to a model whose parameters are ``parameters``.

        A model's functions take the values as a vector in model order, so a set built
        for another model (other effects, another latch law) would be read by position.

        Parameters
        ----------
        parameters : iterable of Parameter
            The model's parameters, in model order.
        model_name : str
            The model's name, for the message.

        Returns
        -------
        ParameterSet
            ``self`` when built for these parameters; a set rebuilt in the model's order
            and checked against its bounds when the names are the same.

        Raises
        ------
        ModelError
            If the parameter names differ: lists the model's parameters missing from the
            set and the set's parameters the model does not have.
        """
        parameters = tuple(parameters)
        if parameters is self.parameters or parameters == self.parameters:
            return self
        mine = [p.name for p in self.parameters]
        theirs = [p.name for p in parameters]
        missing = [n for n in theirs if n not in frozenset(mine)]
        extra = [n for n in mine if n not in frozenset(theirs)]
        if missing or extra:
            problems = []
            if missing:
                problems.append(f"missing (the model has them): {', '.join(missing)}")
            if extra:
                problems.append(f"extra (the model does not have them): {', '.join(extra)}")
            raise ModelError(
                f"the parameter set was built for another model, not for {model_name} "
                f"(the set has {len(mine)} parameters, the model {len(theirs)}); build it "
                "with model.default_params() or model.params(...):\n  - " + "\n  - ".join(problems)
            )
        return ParameterSet(parameters, dict(self.values))

    @classmethod
    def from_json(cls, parameters: Iterable[Parameter], source: str | Path) -> ParameterSet:
        """Read values written by :meth:`to_json` (a path or JSON text); units are checked.

        Parameters
        ----------
        parameters : iterable of Parameter
            The model's parameters.
        source : str or Path
            A file, or JSON text (starting with ``{`` or ``[``):
            ``{"parameters": {name: {"value": v, "unit": u}}}``, values in ``u``, which must be
            the parameter's unit. Parameters not listed keep their defaults.

        Returns
        -------
        ParameterSet

        Raises
        ------
        ModelError
            If the file cannot be read or is not JSON, or listing every problem of the
            content: a missing or misspelt top-level key, an entry that is not
            ``{"value": number, "unit": str}``, an unknown parameter, a wrong unit, a value
            not finite or outside its bounds.
        """
        parameters = tuple(parameters)
        where = "parameter JSON text"
        if _is_path(source):
            where = f"parameter file {source}"
            try:
                text = Path(source).read_text(encoding="utf-8")
            except (OSError, ValueError) as exc:
                raise ModelError(f"cannot read {where}: {exc}") from exc
        else:
            text = str(source)
        try:
            doc = json.loads(text)
        except (json.JSONDecodeError, RecursionError) as exc:
            raise ModelError(f"{where} is not JSON: {exc}") from exc
        values, problems = _read_values(doc, {p.name: p for p in parameters})
        if problems:
            raise ModelError(f"invalid {where}:\n  - " + "\n  - ".join(problems))
        return cls(parameters, values)


#: Most changed values a ParameterSet's repr lists.
_REPR_CHANGED = 12

#: Whether a new set is checked for values that defeat a component (off inside from_vector).
_DESIGN_CHECKS: contextvars.ContextVar[bool] = contextvars.ContextVar(
    "clutchlab_design_checks", default=True
)

#: Kinds of :class:`ParameterWarning` given so far in this process (each is given once).
_WARNED: set[str] = set()


@contextlib.contextmanager
def without_design_checks() -> Iterator[None]:
    """Parameter sets built inside give no :class:`~clutchlab.errors.ParameterWarning`.

    For the sets a fit or a discovery makes on its way (iterates, staged-start probes,
    candidate starts): the user did not write those values, and a probe that leaves the
    latch valve without snap action on the way is no mistake of theirs.
    """
    token = _DESIGN_CHECKS.set(False)
    try:
        yield
    finally:
        _DESIGN_CHECKS.reset(token)


def quiet_design_checks(fn):
    """Decorator: ``fn`` runs :func:`without_design_checks` (a fit's own parameter sets)."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with without_design_checks():
            return fn(*args, **kwargs)

    return wrapper


def _warn_design(values: Mapping[str, float]) -> None:
    """Warn (once per process) when ``values`` leave the latch valve unable to latch."""
    if "latch" in _WARNED:
        return
    from .components.latch import latch_snap_problem  # the components import this module

    problem = latch_snap_problem(values)
    if problem is None:
        return
    warn_at_caller(f"{problem} (this warning is given once per Python process)", ParameterWarning)
    _WARNED.add("latch")  # after warn: a warning turned into an error is raised every time


def _unknown(name: str, known: Iterable[str] = ()) -> str:
    """The problem of an unknown parameter; one of an effect the model lacks names it, a
    misspelt one the closest known names."""
    from .effects import missing_effect  # the effects declare their parameters here

    missing = missing_effect(name)
    if missing is None:
        close = difflib.get_close_matches(str(name), list(known), n=3)
        hint = f" (did you mean {', '.join(map(repr, close))}?)" if close else ""
        return f"unknown parameter {name!r}{hint}"
    owner, text = missing
    return f"unknown parameter {name!r}: it {text} (CircuitModel().with_effects({owner!r}))"


def _read_values(doc, specs: dict[str, Parameter]) -> tuple[dict[str, float], list[str]]:
    """Values and every problem of a :meth:`ParameterSet.to_json` document."""
    if not isinstance(doc, dict):
        return {}, [f'the top level must be an object {{"parameters": ...}}, not {_kind(doc)}']
    problems = []
    for key in doc:
        if key != "parameters":
            close = difflib.get_close_matches(str(key), ["parameters"], n=1)
            hint = " (did you mean 'parameters'?)" if close else ""
            problems.append(f"unknown top-level key {key!r}{hint}")
    if "parameters" not in doc:
        problems.append("the top-level key 'parameters' is missing")
        return {}, problems
    entries = doc["parameters"]
    if not isinstance(entries, dict):
        return {}, [*problems, f"'parameters' must be an object, not {_kind(entries)}"]
    values = {}
    for name, entry in entries.items():
        spec = specs.get(name)
        if spec is None:
            close = difflib.get_close_matches(str(name), list(specs), n=1)
            hint = f" (did you mean {close[0]!r}?)" if close else ""
            problems.append(f"{name}: unknown parameter{hint}")
            continue
        if not isinstance(entry, dict):
            problems.append(f'{name}: must be {{"value": ..., "unit": ...}}, not {_kind(entry)}')
            continue
        for key in entry:
            if key not in ("value", "unit"):
                problems.append(f"{name}: unknown key {key!r} (an entry has 'value' and 'unit')")
        unit_ok = entry.get("unit") == spec.unit
        if "unit" not in entry:
            problems.append(f"{name}: 'unit' is missing (expected {spec.unit!r})")
        elif not unit_ok:
            problems.append(f"{name}: unit {entry['unit']!r}, expected {spec.unit!r}")
        value = entry.get("value")
        if "value" not in entry:
            problems.append(f"{name}: 'value' is missing")
        elif not isinstance(value, int | float) or isinstance(value, bool):
            problems.append(f"{name}: value {value!r} is not a number")
        else:
            msg = spec.check(float(value)) if unit_ok else None  # bounds are in spec.unit
            if msg:
                problems.append(msg)
            values[name] = float(value)
    return values, problems


def _kind(value) -> str:
    """A JSON value's kind, for messages (``a list``, ``a string``)."""
    kinds = {dict: "an object", list: "a list", str: "a string", bool: "a boolean"}
    if value is None:
        return "null"
    return kinds.get(type(value), "a number")


def _is_path(source) -> bool:
    """A file name, not JSON text (which starts with an object or a list)."""
    if isinstance(source, Path):
        return True
    s = str(source)
    return not s.lstrip().startswith(("{", "[")) and len(s) < 4096
