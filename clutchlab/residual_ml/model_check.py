"""One validation step for saved residual_ml models: load, save and FMU export all use it.

A saved model is a JSON document (format tag, version, class, constructor parameters,
learned state) and an NPZ of arrays (:mod:`~clutchlab.residual_ml.persist`).
:func:`check_model_document` checks both before anything is built from them:

- the format tag and version are known, the class and every nested class are from the
  allow-list (:data:`MODEL_CLASSES`), the array file is a bare file name beside the JSON;
- every required key is there and of the right type, no unknown key is;
- constructor parameters are in range (positive widths and tolerances, known kernels,
  features, classifiers), the physics of a hybrid is a valid effects + parameters set
  (known names, finite values inside their bounds);
- every array is there, numeric, of the shape the others imply (``d`` features, ``n`` GP
  bins, ``m`` std bins, ``c`` classifier columns), finite, and positive where it is a scale
  (standardization scales, bin weights and widths); the log-hyperparameters give finite,
  positive variances and length scales; no array is left over.

It collects every problem and raises one :class:`~clutchlab.errors.ModelFileError`
naming the file and, per problem, the key or array. :func:`check_model` runs the same
check on a fitted model in memory (its document as :func:`save_model` would write it):
``clutchlab export-fmu`` calls it before it writes anything, ``save_model`` before it
writes the files.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from pathlib import PurePosixPath, PureWindowsPath

import numpy as np

from ..errors import ClutchlabError, ModelFileError
from .classifiers import CLASSIFIERS, KernelDecision, LinearDecision
from .estimators import (
    LATCH_MODELS,
    STD_OPTIONS,
    GPBaseline,
    GPWithDerivative,
    SVCPartitionedGP,
)
from .features import FEATURES
from .hybrid import HybridModel
from .kernels import KERNELS, kernel_spec
from .labels import LatchLabelRule
from .latch_event import EventDecision
from .latch_local import LocalEventDecision
from .local_gp import LocalGPRegressor
from .physics import PhysicsPredictor

__all__ = ["FORMAT", "FORMAT_VERSIONS", "MODEL_CLASSES", "check_model", "check_model_document"]

#: Format tag of every model JSON.
FORMAT = "clutchlab.residual_ml"
#: Format versions this release reads.
FORMAT_VERSIONS: tuple[int, ...] = (1,)
#: Classes a model file may name (top level and nested ``__estimator__``), by name.
MODEL_CLASSES: dict[str, type] = {
    c.__name__: c for c in (GPBaseline, GPWithDerivative, SVCPartitionedGP, HybridModel)
}
#: Most ROS2 substeps per sample a saved physics may ask for.
MAX_SUBSTEPS = 1000
#: Largest standardized bin point (standard deviations of the training features): the
#: weighted standardization of n samples bounds it by about √n, 10³ for 10⁶ samples.
MAX_STANDARDIZED = 1e6
#: Floor of a fitted scale relative to max(1, |mean|): the fit replaces a smaller standard
#: deviation by 1 (``LocalGPRegressor.fit``).
_SCALE_FLOOR = 1e-12

_MISSING = object()
#: Saved latch decisions by their ``kind`` (the model file's ``decision``).
DECISIONS = {
    KernelDecision.kind: KernelDecision,
    LinearDecision.kind: LinearDecision,
    EventDecision.kind: EventDecision,
    LocalEventDecision.kind: LocalEventDecision,
}


def _real(value) -> float | None:
    """``value`` as a float if it is a JSON/NumPy real number (not a bool), else None."""
    if isinstance(value, bool | np.bool_) or not isinstance(value, int | float | np.number):
        return None
    if isinstance(value, complex | np.complexfloating):
        return None
    try:
        return float(value)
    except OverflowError:
        return math.inf if value > 0 else -math.inf


def _is_int(value) -> bool:
    return isinstance(value, int | np.integer) and not isinstance(value, bool | np.bool_)


def _number(lo: float | None = None, strict: bool = False, nan_ok: bool = False):
    """Rule: a finite real number (``> lo`` if strict, else ``>= lo``)."""

    def rule(value) -> str | None:
        x = _real(value)
        if x is None:
            return f"must be a number, got {value!r}"
        if math.isnan(x) and nan_ok:
            return None
        if not math.isfinite(x):
            return f"must be finite, got {value!r}"
        if lo is not None and (x <= lo if strict else x < lo):
            return f"must be {'>' if strict else '>='} {lo:g}, got {value!r}"
        return None

    return rule


def _integer(lo: int | None = None, hi: int | None = None):
    def rule(value) -> str | None:
        if not _is_int(value):
            return f"must be an integer, got {value!r}"
        if lo is not None and value < lo:
            return f"must be >= {lo}, got {value!r}"
        if hi is not None and value > hi:
            return f"must be <= {hi}, got {value!r}"
        return None

    return rule


def _one_of(choices):
    choices = tuple(choices)

    def rule(value) -> str | None:
        if not isinstance(value, str) or value not in choices:
            return f"must be one of {', '.join(choices)}, got {value!r}"
        return None

    return rule


def _boolean(value) -> str | None:
    return None if isinstance(value, bool) else f"must be true or false, got {value!r}"


def _optional(rule):
    return lambda value: None if value is None else rule(value)


def _names(known, empty_ok: bool = False):
    """Rule: a list of distinct names from ``known``."""

    def rule(value) -> str | None:
        if not isinstance(value, list | tuple):
            return f"must be a list of names, got {value!r}"
        bad = [v for v in value if not isinstance(v, str) or v not in known]
        if bad:
            return f"unknown name(s) {bad!r}; known: {', '.join(known)}"
        if not value and not empty_ok:
            return "must not be empty"
        if len(set(value)) != len(value):
            return f"repeats a name: {list(value)!r}"
        return None

    return rule


def _auto_or(rule):
    """Rule: ``"auto"`` or what ``rule`` accepts."""

    def either(value) -> str | None:
        if value == "auto":
            return None
        problem = rule(value)
        return None if problem is None else "must be 'auto' or " + problem.removeprefix("must be ")

    return either


#: Rule of every constructor parameter of :data:`MODEL_CLASSES` (None: a nested object,
#: checked by its own method of ``_Checker``: label rule, physics, residual estimator).
_PARAM_RULES: dict[str, Callable | None] = {
    "features": _optional(_names(tuple(FEATURES))),
    "classifier_features": _optional(_names(tuple(FEATURES))),
    "didt_periods": _number(0.0, strict=True),
    "target": _one_of(("period_mean", "raw")),
    "lag_s": _auto_or(_number(0.0)),
    "kernel": _optional(_one_of(KERNELS)),
    "ard": _boolean,
    "bin_width": _number(0.0, strict=True),
    "bin_frac": _number(0.0, strict=True),
    "max_points": _integer(1),
    "n_hyper": _integer(1),
    "n_restarts": _integer(0),
    "knot_tol": _number(0.0),
    "max_knot_gap": _integer(1),
    "random_state": _optional(_integer(0, 2**32 - 1)),
    "event_points": _one_of(("exclude", "assign")),
    "latch_model": _one_of(LATCH_MODELS),
    "latch_bandwidth": _number(0.0, strict=True),
    "latch_line": _one_of(("auto", "off")),
    "latched_reference": _one_of(("line", "none")),
    **{name: _one_of(choices) for name, choices in STD_OPTIONS.items()},
    "latch_rate_scale": _optional(_number(0.0)),
    "pressure_rate_scale": _number(0.0),
    "classifier": _one_of(CLASSIFIERS),
    "svc_C": _number(0.0, strict=True),
    "svc_gamma": _number(0.0, strict=True),
    "svc_max_points": _integer(1),
    "label_rule": None,
    "physics": None,
    "residual": None,
    "form": _one_of(("auto", "residual", "standalone", "physics")),
    "form_folds": _integer(2),
    "standalone_handicap": _auto_or(_number(0.0, strict=True)),
}


class _Checker:
    """Collects the problems of one model document and its arrays."""

    def __init__(self, arrays: Mapping[str, np.ndarray] | None, npz_name: str) -> None:
        self.skip_arrays = arrays is None
        self.arrays = {} if arrays is None else arrays
        self.npz = npz_name
        self.problems: list[str] = []
        self.used: set[str] = set()
        self.claimed: list[str] = []  # prefixes whose arrays could not be checked

    def add(self, where: str, message: str) -> None:
        self.problems.append(f"{where}: {message}")

    # -- keys ------------------------------------------------------------------------------

    def mapping(self, value, where: str) -> dict | None:
        if not isinstance(value, dict):
            self.add(where, f"must be a JSON object, got {type(value).__name__}")
            return None
        return value

    def key(self, d: dict, key: str, where: str, rule=None, required: bool = True):
        """``d[key]`` checked by ``rule``; _MISSING (and a problem if required) when absent
        or invalid."""
        if key not in d:
            if required:
                self.add(f"{where}.{key}" if where else key, "missing key")
            return _MISSING
        value = d[key]
        if rule is not None:
            problem = rule(value)
            if problem:
                self.add(f"{where}.{key}" if where else key, problem)
                return _MISSING
        return value

    def unknown(self, d: dict, known, where: str) -> None:
        extra = sorted(str(k) for k in d if k not in known)
        if extra:
            self.add(where or "document", f"unknown key(s) {', '.join(extra)}")

    # -- arrays ----------------------------------------------------------------------------

    def array(
        self,
        name: str,
        shape: tuple,
        positive: bool = False,
        inf_ok: bool = False,
        required: bool = True,
    ) -> np.ndarray | None:
        """Array ``name`` of ``shape`` (None: any length), finite (or +inf if ``inf_ok``),
        and > 0 if ``positive``; None (and a problem) otherwise."""
        where = f"array {name!r} in {self.npz}"
        if self.skip_arrays:
            return None
        if name not in self.arrays:
            if required:
                self.add(where, "missing")
            return None
        self.used.add(name)
        a = self.arrays[name]
        if not isinstance(a, np.ndarray) or a.dtype.kind not in "fiu":
            kind = a.dtype if isinstance(a, np.ndarray) else type(a).__name__
            self.add(where, f"must hold real numbers, has dtype {kind}")
            return None
        want = "(" + ", ".join("n" if s is None else str(s) for s in shape)
        want += ",)" if len(shape) == 1 else ")"
        fits = a.ndim == len(shape) and all(
            s is None or s == t for s, t in zip(shape, a.shape, strict=True)
        )
        if not fits:
            self.add(where, f"has shape {a.shape}, expected {want}")
            return None
        if a.size == 0:
            self.add(where, f"is empty, expected {want} with n >= 1")
            return None
        x = np.asarray(a, dtype=float)
        bad = np.isnan(x) | (np.isinf(x) if not inf_ok else np.isneginf(x))
        if positive:
            bad |= ~(x > 0)
        if bad.any():
            first = tuple(int(i) for i in np.argwhere(bad)[0])
            what = "positive" if positive else "finite"
            what += " (or +inf)" if inf_ok else ""
            self.add(
                where,
                f"{int(bad.sum())} value(s) not {what}, first at index "
                f"{first[0] if len(first) == 1 else first}: {float(x[first])!r}",
            )
            return None
        return x

    def claim(self, prefix: str) -> None:
        """Arrays under ``prefix`` belong to a part that could not be checked."""
        self.claimed.append(prefix)

    def leftover(self) -> None:
        if self.skip_arrays:
            return
        extra = sorted(
            k
            for k in self.arrays
            if k not in self.used and not any(k.startswith(p) for p in self.claimed)
        )
        if extra:
            self.add(f"arrays in {self.npz}", f"unexpected array(s) {', '.join(map(repr, extra))}")

    # -- parameters ------------------------------------------------------------------------

    def params(self, cls: type, params, where: str) -> dict | None:
        """Constructor parameters of ``cls``; returns them as checked (None if not a dict)."""
        params = self.mapping(params, where)
        if params is None:
            return None
        known = cls._get_param_names()
        self.unknown(params, known, where)
        for name in known:
            if name not in params:
                continue  # a file written before this parameter existed: its default
            rule = _PARAM_RULES.get(name)
            value = params[name]
            if rule is not None:
                problem = rule(value)
                if problem:
                    self.add(f"{where}.{name}", problem)
            elif name == "label_rule":
                self.label_rule(value, f"{where}.{name}")
            elif name == "physics":
                if value is not None:
                    self.physics(value, f"{where}.{name}", wrapped=True)
            elif name == "residual":
                self.residual_param(value, f"{where}.{name}")
        return params

    def label_rule(self, value, where: str) -> None:
        if value is None:
            return
        value = self.mapping(value, where)
        if value is None:
            return
        self.unknown(value, ("__rule__",), where)
        rule = self.key(value, "__rule__", where)
        rule = self.mapping(rule, where + ".__rule__") if rule is not _MISSING else None
        if rule is None:
            return
        w = where + ".__rule__"
        keys = ("margin_bar", "hysteresis_bar", "event_band_bar", "max_event_s")
        self.unknown(rule, keys, w)
        ok = True
        for k in ("margin_bar", "hysteresis_bar", "max_event_s"):
            ok &= self.key(rule, k, w, _number()) is not _MISSING
        band = self.key(rule, "event_band_bar", w, _pair)
        if not ok or band is _MISSING:
            return
        try:
            LatchLabelRule.from_dict(rule)
        except ClutchlabError as exc:
            self.add(w, _one_line(exc))

    def physics(self, value, where: str, wrapped: bool = False) -> None:
        """A PhysicsPredictor description (``{"__physics__": {...}}`` if ``wrapped``)."""
        value = self.mapping(value, where)
        if value is None:
            return
        if wrapped:
            self.unknown(value, ("__physics__",), where)
            value = self.key(value, "__physics__", where)
            where += ".__physics__"
            if value is _MISSING or (value := self.mapping(value, where)) is None:
                return
        self.unknown(value, ("kind", "effects", "params", "substeps", "train_experiments"), where)
        ok = self.key(value, "kind", where, _one_of(("PhysicsPredictor",))) is not _MISSING
        effects = self.key(value, "effects", where, _str_list)
        params = self.key(value, "params", where, _real_dict)
        ok &= self.key(value, "substeps", where, _integer(1, MAX_SUBSTEPS)) is not _MISSING
        # the experiments the physics was fitted on (files before it: none recorded)
        trained = self.key(value, "train_experiments", where, _str_list, required=False)
        ok &= trained is not _MISSING or "train_experiments" not in value
        if not ok or effects is _MISSING or params is _MISSING:
            return
        try:
            PhysicsPredictor.from_dict(value)
        except ClutchlabError as exc:  # unknown effect or parameter, value out of bounds
            self.add(where, _one_line(exc))

    def residual_param(self, value, where: str) -> None:
        if value is None:
            return
        value = self.mapping(value, where)
        if value is None:
            return
        self.unknown(value, ("__estimator__",), where)
        spec = self.key(value, "__estimator__", where)
        where += ".__estimator__"
        if spec is _MISSING or (spec := self.mapping(spec, where)) is None:
            return
        self.unknown(spec, ("class", "params"), where)
        cls = self.key(spec, "class", where, _one_of(_RESIDUAL_CLASSES))
        params = self.key(spec, "params", where)
        if cls is not _MISSING and params is not _MISSING:
            self.params(MODEL_CLASSES[cls], params, where + ".params")

    # -- learned state ---------------------------------------------------------------------

    def state(self, cls: type, params: dict | None, state, where: str, prefix: str) -> None:
        """Learned state of a ``cls`` and its arrays (names under ``prefix``)."""
        state = self.mapping(state, where)
        if state is None:
            self.claim(prefix)
            return
        common = ("feature_names", "train_experiments", "n_features_in", "lag_s")
        own = {
            HybridModel: ("physics", "residual", "form", "form_scores", "standalone_handicap"),
            SVCPartitionedGP: (
                "classifier_columns",
                "classifier_train_accuracy",
                "single_state",
                "latched_reference",
                "latch_timing",
                "train_log_rates",
                "noise_by_freq",
                "decision",
                "gps",
            ),
        }.get(cls, ("gp", "train_log_rates", "variance_floor"))
        self.unknown(state, common + own, where)
        names = self.key(state, "feature_names", where, _names_any)
        self.key(state, "train_experiments", where, _str_list)
        d = len(names) if names is not _MISSING else None
        n_in = self.key(state, "n_features_in", where, _integer(1))
        if d is not None and n_in is not _MISSING and n_in != d:
            self.add(f"{where}.n_features_in", f"is {n_in}, but there are {d} feature_names")
        self.key(state, "lag_s", where, _number(0.0), required=False)
        if cls is HybridModel:
            self.hybrid(state, where, prefix, names)
            return
        if names is not _MISSING and params is not None:
            self.feature_match(cls, params, names, where)
        if cls is SVCPartitionedGP:
            self.partitioned(state, where, prefix, d)
            return
        self.key(state, "train_log_rates", where, _number_list, required=False)
        floor = self.key(state, "variance_floor", where, required=False)
        if floor is not _MISSING and floor is not None:
            self.gp(floor, f"{where}.variance_floor", prefix + "floor.", d)
        meta = self.key(state, "gp", where)
        if meta is _MISSING:
            self.claim(prefix + "gp.")
            return
        self.gp(meta, f"{where}.gp", prefix + "gp.", d)

    def feature_match(self, cls: type, params: dict, names: list, where: str) -> None:
        """The saved feature names are those the parameters build (or ``x0…`` for a model
        fitted on arrays): otherwise a trace's feature matrix has other columns."""
        feats = params.get("features")
        if _PARAM_RULES["features"](feats) is not None:
            return  # reported with the parameters
        built = list(feats) if feats else list(cls._default_features)
        if list(names) != built and list(names) != [f"x{j}" for j in range(len(names))]:
            self.add(
                f"{where}.feature_names",
                f"{list(names)!r} are not the features the parameters build ({built!r})",
            )

    def hybrid(self, state: dict, where: str, prefix: str, names) -> None:
        forms = ("residual", "standalone", "physics")
        self.key(state, "form", where, _one_of(forms), required=False)
        scores = self.key(state, "form_scores", where, required=False)
        if scores is not _MISSING and (scores := self.mapping(scores, f"{where}.form_scores")):
            for k, v in scores.items():
                problem = _one_of(forms)(k) or _number(0.0)(v)
                if problem:
                    self.add(f"{where}.form_scores.{k}", problem)
        self.key(
            state,
            "standalone_handicap",
            where,
            _optional(_number(0.0, strict=True)),
            required=False,
        )
        phys = self.key(state, "physics", where)
        if phys is not _MISSING and phys is not None:
            self.physics(phys, f"{where}.physics")
        res = self.key(state, "residual", where)
        w = f"{where}.residual"
        if res is _MISSING or (res := self.mapping(res, w)) is None:
            self.claim(prefix + "residual")
            return
        self.unknown(res, ("class", "params", "state"), w)
        cls = self.key(res, "class", w, _one_of(_RESIDUAL_CLASSES))
        params = self.key(res, "params", w)
        rstate = self.key(res, "state", w)
        if cls is _MISSING or rstate is _MISSING:
            self.claim(prefix + "residual")
            return
        cls = MODEL_CLASSES[cls]
        checked = self.params(cls, params, w + ".params") if params is not _MISSING else None
        self.state(cls, checked, rstate, w + ".state", prefix + "residual")
        inner = rstate.get("feature_names") if isinstance(rstate, dict) else None
        if names is not _MISSING and isinstance(inner, list) and inner != names:
            self.add(
                f"{where}.feature_names",
                f"{names!r} differ from the residual model's {inner!r}",
            )

    def latch_timing(self, timing, where: str) -> None:
        """The switch-current error model (:class:`~.latch_timing.LatchTiming`)."""
        timing = self.mapping(timing, where)
        if timing is None:
            return
        per_direction = {
            "fit_rms_mA": _number(0.0),
            "log_rates": _number_list,
            "currents_mA": _number_list,
            "n_errors": _integer(0),
            "n_missed": _integer(0),
        }
        self.unknown(timing, tuple(per_direction), where)
        for key, rule in per_direction.items():
            d = self.key(timing, key, where)
            if d is _MISSING or (d := self.mapping(d, f"{where}.{key}")) is None:
                continue
            self.unknown(d, ("on", "off"), f"{where}.{key}")
            for direction in ("on", "off"):
                self.key(d, direction, f"{where}.{key}", rule)
        for direction in ("on", "off"):
            rates = timing.get("log_rates", {})
            currents = timing.get("currents_mA", {})
            if isinstance(rates, dict) and isinstance(currents, dict):
                a, c = rates.get(direction), currents.get(direction)
                if isinstance(a, list) and isinstance(c, list) and len(a) != len(c):
                    self.add(
                        f"{where}.currents_mA.{direction}",
                        f"has {len(c)} values for {len(a)} log_rates",
                    )

    def partitioned(self, state: dict, where: str, prefix: str, d: int | None) -> None:
        cols = self.key(state, "classifier_columns", where, _column_list(d))
        self.key(state, "classifier_train_accuracy", where, _fraction)
        single = self.key(state, "single_state", where, _optional(_integer(0, 1)))
        self.key(state, "latched_reference", where, _one_of(("line", "none")), required=False)
        self.key(state, "train_log_rates", where, _number_list, required=False)
        self.key(state, "noise_by_freq", where, _noise_by_freq, required=False)
        timing = self.key(state, "latch_timing", where, required=False)
        if timing is not _MISSING and timing is not None:
            self.latch_timing(timing, f"{where}.latch_timing")
        kind = self.key(state, "decision", where, _optional(_one_of(DECISIONS)))
        if kind is None and single is None:
            self.add(f"{where}.single_state", "must be 0 or 1 when there is no decision")
        if kind is _MISSING or cols is _MISSING or kind is None:
            self.claim(prefix + "clf.")
        else:
            self.decision(kind, prefix + "clf.", len(cols))
        gps = self.key(state, "gps", where)
        w = f"{where}.gps"
        if gps is _MISSING or (gps := self.mapping(gps, w)) is None:
            self.claim(prefix + "gp")
            return
        if not gps:
            self.add(w, "no GP (expected one for latch state 0 and/or 1)")
        bad = [g for g in gps if g not in ("0", "1")]
        if bad:
            self.add(w, f"unknown latch state(s) {bad!r}; expected '0' and/or '1'")
        for g, meta in gps.items():
            if g in ("0", "1"):
                self.gp(meta, f"{w}.{g}", f"{prefix}gp{g}.", d)

    def decision(self, kind: str, prefix: str, c: int) -> None:
        a = self.array
        if kind == EventDecision.kind:
            cols = a(prefix + "columns", (5,))
            if cols is not None and not all(-1 <= v < c and v == int(v) for v in cols):
                self.add(prefix + "columns", f"must be column indices below {c} or -1")
            a(prefix + "on", (5,))
            a(prefix + "off", (5,))
            return
        if kind == LocalEventDecision.kind:
            cols = a(prefix + "columns", (5,))
            if cols is not None and not all(-1 <= v < c and v == int(v) for v in cols):
                self.add(prefix + "columns", f"must be column indices below {c} or -1")
            for side in ("on", "off"):
                ev = a(prefix + side, (None, 4))
                if ev is not None and ev.shape[0] < 2:
                    self.add(prefix + side, "needs at least two latch events")
            a(prefix + "scale", (2,), positive=True)
            a(prefix + "bandwidth", (1,), positive=True)
            a(prefix + "slope", (2,), positive=True)
            a(prefix + "line", (4,), required=False)  # files before the line coupling: none
            a(prefix + "censored", (None, 3), required=False)  # files before it: none
            return
        a(prefix + "mean", (c,))
        a(prefix + "scale", (c,), positive=True, inf_ok=True)  # inf: a feature weighted 0
        a(prefix + "intercept", (1,))
        if kind == LinearDecision.kind:
            a(prefix + "weights", (c,))
            return
        support = a(prefix + "support", (None, c))
        n_sv = support.shape[0] if support is not None else None
        a(prefix + "coef", (n_sv,))
        a(prefix + "gamma", (1,), positive=True)

    def gp(self, meta, where: str, prefix: str, d: int | None) -> None:
        """One LocalGPRegressor: its JSON part (``meta``) and its arrays.

        Beyond shapes and finiteness, the invariants every fit leaves: log-hyperparameters
        inside the optimizer's bounds (:meth:`LocalGPRegressor._bounds`), scales above
        ``1e-12·max(1, |mean|)`` (the floor the fit puts on them), standardized bin points
        within :data:`MAX_STANDARDIZED` standard deviations, and bin noise ``σ²/w`` and the
        mean's weights ``Σ|K⁻¹y|·s²·y_scale`` finite: then the mean and standard deviation
        are finite for every finite input.
        """
        meta = self.mapping(meta, where)
        if meta is None:
            self.claim(prefix)
            return
        keys = ("kernel", "ard", "n_dims", "y_mean", "y_scale", "n_features_in")
        self.unknown(meta, (*keys, "log_marginal_likelihood"), where)
        kernel = self.key(meta, "kernel", where, _one_of(KERNELS))
        ard = self.key(meta, "ard", where, _boolean)
        for k in ("n_dims", "n_features_in"):
            n = self.key(meta, k, where, _integer(1))
            if n is not _MISSING and d is not None and n != d:
                self.add(f"{where}.{k}", f"is {n}, but the model has {d} features")
        y_mean = self.key(meta, "y_mean", where, _number())
        y_scale = self.key(meta, "y_scale", where, _number(0.0, strict=True))
        if y_mean is not _MISSING and y_scale is not _MISSING:
            if not float(y_scale) > _SCALE_FLOOR * max(1.0, abs(float(y_mean))):
                self.add(
                    f"{where}.y_scale",
                    f"{y_scale!r} is below {_SCALE_FLOOR:g}·max(1, |y_mean|) (no fit gives it)",
                )
        self.key(meta, "log_marginal_likelihood", where, _number(nan_ok=True))
        a = self.array
        theta = None
        if kernel is not _MISSING and ard is not _MISSING and d is not None:
            spec = kernel_spec(kernel, d, ard)
            theta = a(prefix + "theta", (spec.n_params + 1,))
            if theta is not None:
                bounds = LocalGPRegressor()._bounds(spec)
                tol = 1e-9 * np.maximum(1.0, np.abs(bounds))
                bad = (theta < bounds[:, 0] - tol[:, 0]) | (theta > bounds[:, 1] + tol[:, 1])
                if bad.any():
                    names = [
                        spec.param_names[i] if i < spec.n_params else "log_noise_var"
                        for i in np.flatnonzero(bad)
                    ]
                    self.add(
                        f"array {prefix + 'theta'!r} in {self.npz}",
                        f"log-hyperparameter(s) {', '.join(names)} = "
                        f"{theta[bad].tolist()!r} outside the fit's bounds "
                        f"{bounds[bad].tolist()!r}",
                    )
                    theta = None
        else:
            self.used.add(prefix + "theta")
        x_mean = a(prefix + "x_mean", (d,))
        x_scale = a(prefix + "x_scale", (d,), positive=True)
        if x_mean is not None and x_scale is not None:
            low = ~(x_scale > _SCALE_FLOOR * np.maximum(1.0, np.abs(x_mean)))
            if low.any():
                self.add(
                    f"array {prefix + 'x_scale'!r} in {self.npz}",
                    f"value(s) at index {np.flatnonzero(low).tolist()} below "
                    f"{_SCALE_FLOOR:g}·max(1, |x_mean|) (no fit gives them)",
                )
        a(prefix + "bin_widths", (d,), positive=True)
        pts = self.standardized(prefix + "X_bins", d)
        n = pts.shape[0] if pts is not None else None
        a(prefix + "y_bins", (n,))
        w = a(prefix + "w_bins", (n,), positive=True)
        dual = a(prefix + "dual_coef", (n,))
        names = [prefix + k for k in ("X_std_bins", "w_std_bins", "std_bin_widths")]
        present = [k in self.arrays for k in names]
        w_std = None
        if any(present[:2]) or present[2]:  # written since the std bins exist: all three
            std = self.standardized(names[0], d)
            w_std = a(names[1], (std.shape[0] if std is not None else None,), positive=True)
            a(names[2], (d,), positive=True)
        if theta is None:
            return
        with np.errstate(over="ignore", divide="ignore"):
            noise, s2 = math.exp(theta[-1]), math.exp(theta[0])
            for name, weights in ((prefix + "w_bins", w), (names[1], w_std)):
                if weights is not None and not np.isfinite(noise / weights).all():
                    self.add(
                        f"array {name!r} in {self.npz}",
                        "weight(s) so small that the bin noise σ²/w is infinite",
                    )
            if dual is not None and y_scale is not _MISSING and y_mean is not _MISSING:
                total = abs(float(y_mean)) + np.sum(np.abs(dual)) * s2 * float(y_scale)
                if not np.isfinite(total):
                    self.add(
                        f"array {prefix + 'dual_coef'!r} in {self.npz}",
                        "weights so large that the predictive mean overflows",
                    )

    def standardized(self, name: str, d: int | None) -> np.ndarray | None:
        """Bin points in standard deviations: n × d, within :data:`MAX_STANDARDIZED`."""
        pts = self.array(name, (None, d))
        if pts is not None and np.abs(pts).max() > MAX_STANDARDIZED:
            self.add(
                f"array {name!r} in {self.npz}",
                f"standardized value(s) beyond {MAX_STANDARDIZED:g} standard deviations",
            )
            return None
        return pts


def _one_line(exc: Exception) -> str:
    """An error's message, its problem list joined into one line."""
    return str(exc).replace(":\n  - ", ": ").replace("\n  - ", "; ").replace("\n", " ")


def _pair(value) -> str | None:
    if not isinstance(value, list | tuple) or len(value) != 2:
        return f"must be a list of two numbers, got {value!r}"
    for v in value:
        problem = _number()(v)
        if problem:
            return problem
    return None


def _str_list(value) -> str | None:
    if not isinstance(value, list | tuple) or not all(isinstance(v, str) for v in value):
        return f"must be a list of strings, got {value!r}"
    return None


def _noise_by_freq(value) -> str | None:
    if not isinstance(value, dict):
        return f"must be a JSON object, got {value!r}"
    for g, pair in value.items():
        if g not in ("0", "1"):
            return f"keys must be latch states '0' / '1', got {g!r}"
        problem = _pair(pair)
        if problem is None and min(pair) < 0:
            problem = f"must be two numbers >= 0, got {pair!r}"
        if problem:
            return f"{g}: {problem}"
    return None


def _number_list(value) -> str | None:
    if not isinstance(value, list | tuple):
        return f"must be a list of numbers, got {value!r}"
    for v in value:
        problem = _number()(v)
        if problem:
            return problem
    return None


def _names_any(value) -> str | None:
    problem = _str_list(value)
    if problem:
        return problem
    if not value:
        return "must not be empty"
    if len(set(value)) != len(value):
        return f"repeats a name: {list(value)!r}"
    return None


def _real_dict(value) -> str | None:
    if not isinstance(value, dict):
        return f"must be a JSON object of numbers, got {value!r}"
    bad = [k for k, v in value.items() if _real(v) is None]
    return f"value(s) of {bad!r} are not numbers" if bad else None


def _fraction(value) -> str | None:
    x = _real(value)
    if x is None or not 0.0 <= x <= 1.0:
        return f"must be a number in [0, 1], got {value!r}"
    return None


def _column_list(d: int | None):
    def rule(value) -> str | None:
        if not isinstance(value, list) or not value or not all(_is_int(v) for v in value):
            return f"must be a non-empty list of column indices, got {value!r}"
        if d is not None and any(not 0 <= v < d for v in value):
            return f"column indices {value!r} outside 0…{d - 1}"
        if len(set(value)) != len(value):
            return f"repeats a column: {value!r}"
        return None

    return rule


_RESIDUAL_CLASSES = tuple(n for n in MODEL_CLASSES if n != "HybridModel")


def npz_name_problem(value) -> str | None:
    if not isinstance(value, str):
        return f"must be the NPZ file name, got {value!r}"
    bare = (
        value not in ("", ".", "..")
        and PurePosixPath(value).name == value
        and PureWindowsPath(value).name == value
        and "\x00" not in value
    )
    if not bare:
        return f"must be a file name beside the JSON (no folder), got {value!r}"
    if not value.endswith(".npz"):
        return f"must name a .npz file, got {value!r}"
    return None


def check_model_document(
    doc, arrays: Mapping[str, np.ndarray] | None, source: str = "model"
) -> None:
    """Check a saved model's JSON document and its arrays; raise one error listing every
    problem.

    Parameters
    ----------
    doc : object
        The parsed model JSON (what :func:`~clutchlab.residual_ml.save_model` writes).
    arrays : mapping of str to numpy.ndarray, or None
        Every array of the model's NPZ, by name (array units as the model stores them:
        feature units, standardized units, bar); None checks the document alone (before
        the NPZ it names is opened).
    source : str
        The file (or in-memory model) named in the error.

    Raises
    ------
    ModelFileError
        Listing every problem, each naming the key (``state.gps.0.y_scale``) or the array
        (``array 'gp0.x_scale' in m.npz``): missing or unknown keys, wrong types, unknown
        format version or class, array shapes inconsistent with each other, non-finite
        values, non-positive scales, weights and length scales, leftover arrays.
    """
    if not isinstance(doc, dict) or doc.get("format") != FORMAT:
        raise ModelFileError(f"{source} is not a clutchlab residual_ml model (format {FORMAT!r})")
    npz = doc.get("arrays")
    c = _Checker(arrays, npz if isinstance(npz, str) else "the NPZ")
    c.unknown(doc, ("format", "version", "class", "params", "state", "arrays"), "")
    c.key(doc, "version", "", _integer())
    version = doc.get("version")
    if _is_int(version) and version not in FORMAT_VERSIONS:
        known = ", ".join(map(str, FORMAT_VERSIONS))
        c.add("version", f"format version {version} is unknown (this release reads {known})")
    c.key(doc, "arrays", "", npz_name_problem)
    name = c.key(doc, "class", "", _one_of(MODEL_CLASSES))
    params = c.key(doc, "params", "")
    state = c.key(doc, "state", "")
    if name is _MISSING:
        c.claim("")
    else:
        cls = MODEL_CLASSES[name]
        checked = c.params(cls, params, "params") if params is not _MISSING else None
        if state is _MISSING:
            c.claim("")
        else:
            c.state(cls, checked, state, "state", "")
    c.leftover()
    if c.problems:
        raise ModelFileError(f"{source}: not a valid clutchlab model", c.problems)


def check_physics_document(doc, source: str) -> None:
    """Check a :class:`~clutchlab.residual_ml.physics.PhysicsPredictor` description.

    The same check a saved hybrid model's physics goes through: keys and their types, the
    effects and parameters the circuit model knows, the substeps.

    Parameters
    ----------
    doc : object
        The parsed JSON document.
    source : str
        How the error names the document (its file).

    Raises
    ------
    ModelFileError
        Listing every problem found, each naming the key.
    """
    c = _Checker(None, "")
    c.physics(doc, "document")
    if c.problems:
        raise ModelFileError(f"{source}: not a valid PhysicsPredictor description", c.problems)


def check_model(model, source: str | None = None) -> None:
    """Check a fitted model in memory through :func:`check_model_document`.

    The model's document and arrays are built as :func:`~clutchlab.residual_ml.save_model`
    would write them (nothing is written) and checked like a loaded file.

    Parameters
    ----------
    model : GPBaseline, GPWithDerivative, SVCPartitionedGP or HybridModel
        Fitted estimator.
    source : str, optional
        How the error names the model (default ``"in-memory <class>"``).

    Raises
    ------
    ModelFileError
        Listing every problem found (see :func:`check_model_document`).
    ModelError
        If the model is of another class or holds a part that cannot be saved.
    sklearn.exceptions.NotFittedError
        If the model is not fitted.
    """
    from .persist import model_document

    source = source or f"in-memory {type(model).__name__}"
    doc, arrays = model_document(model, "model.npz")
    check_model_document(doc, arrays, source)
