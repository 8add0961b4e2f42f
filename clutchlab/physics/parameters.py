"""Physical parameters: name, unit, default, bounds, scale — and a value set."""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

from ..data.output import write_file_atomic
from ..errors import ModelError
from .units import SI_FACTOR

__all__ = ["Parameter", "ParameterSet"]


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
    """

    parameters: tuple[Parameter, ...]
    values: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        known = {p.name: p for p in self.parameters}
        unknown = sorted(set(self.values) - set(known))
        problems = [f"unknown parameter {n!r}" for n in unknown]
        full = {}
        for p in self.parameters:
            v = float(self.values.get(p.name, p.default))
            msg = p.check(v)
            if msg:
                problems.append(msg)
            full[p.name] = v
        if problems:
            raise ModelError("invalid parameter values:\n  - " + "\n  - ".join(problems))
        object.__setattr__(self, "values", full)

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
        """Inverse of :meth:`vector`."""
        parameters = tuple(parameters)
        vec = np.asarray(vector, dtype=float).ravel()
        if vec.size != len(parameters):
            raise ModelError(f"expected {len(parameters)} values, got {vec.size}")
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

    @classmethod
    def from_json(cls, parameters: Iterable[Parameter], source: str | Path) -> ParameterSet:
        """Read values written by :meth:`to_json` (a path or JSON text); units are checked."""
        parameters = tuple(parameters)
        text = Path(source).read_text(encoding="utf-8") if _is_path(source) else str(source)
        doc = json.loads(text)
        specs = {p.name: p for p in parameters}
        values, problems = {}, []
        for name, entry in doc.get("parameters", {}).items():
            if name in specs and entry.get("unit") != specs[name].unit:
                problems.append(
                    f"{name}: unit {entry.get('unit')!r}, expected {specs[name].unit!r}"
                )
            values[name] = entry["value"]
        if problems:
            raise ModelError("parameter file has wrong units:\n  - " + "\n  - ".join(problems))
        return cls(parameters, values)


def _is_path(source) -> bool:
    if isinstance(source, Path):
        return True
    s = str(source)
    return not s.lstrip().startswith("{") and len(s) < 4096
