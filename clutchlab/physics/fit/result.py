"""The outcome of a physics fit: values, uncertainty, identifiability, per-experiment errors."""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ...data.autocorrelation import lagged_sums
from ...data.output import write_file_atomic
from ...errors import ClutchlabError, FitError, FitResultError
from ..effects import EFFECTS, FLEXIBLE_LAWS, make_effect
from ..model import CircuitModel
from ..parameters import ParameterSet
from ..units import unit_shown

__all__ = [
    "FitResult",
    "ParameterUncertainty",
    "check_fit_document",
    "correlation_note",
    "diverged_sensitivities",
    "identifiability",
    "parameter_uncertainty",
    "residual_correlation_time",
    "training_rms",
]

#: A parameter whose relative standard error exceeds this is reported unidentifiable.
REL_SE_LIMIT = 0.5
#: Singular values (unit-norm columns) below this fraction of the largest mark
#: directions along which parameters trade off exactly (collinear sensitivities).
SV_RATIO_LIMIT = 1e-3
#: Output sensitivities (bar per unit of a scaled free parameter, the solver's coordinates)
#: above this are no linearization of the model: its sensitivity equations diverge there
#: (a locally unstable parameter set, e.g. negative damping), even where the simulated
#: pressure stays finite. Measured: sound fits up to 6e6 (a latch snap on a 0.8 s ramp,
#: where a parameter moves the snap's time), diverged ones 3e29 and 1e89 (two zoo fits that
#: stopped with Error_In_Step_Computation); the limit sits far from both.
SENSITIVITY_LIMIT = 1e15


def training_rms(per_experiment: dict[str, dict[str, float]]) -> float:
    """RMS (bar) over experiments of each one's period-mean RMSE (a fit result's
    ``per_experiment``, or :meth:`PhysicsFitter.training_metrics`); nan when empty."""
    if not per_experiment:
        return float("nan")
    return math.sqrt(sum(m["rmse_bar"] ** 2 for m in per_experiment.values()) / len(per_experiment))


def diverged_sensitivities(jz: np.ndarray) -> str:
    """Why the output sensitivities ``jz`` cannot give standard errors (``""`` when they can).

    Parameters
    ----------
    jz : ndarray
        Residuals (bar) × scaled free parameters.

    Returns
    -------
    str
        Empty, or a sentence for people: the sensitivities are not finite, or larger than
        :data:`SENSITIVITY_LIMIT`; the covariance computed from them would be meaningless
        (standard errors of 1e-40 and every parameter "unidentifiable").
    """
    jz = np.asarray(jz, dtype=float)
    bad = int(np.count_nonzero(~np.isfinite(jz)))
    if bad:
        size = f"{bad} of them not finite"
    else:
        top = float(np.max(np.abs(jz))) if jz.size else 0.0
        if top <= SENSITIVITY_LIMIT:
            return ""
        size = (
            f"up to {top:.3g} bar per scaled parameter unit; sound fits stay many orders "
            f"of magnitude below {SENSITIVITY_LIMIT:g}"
        )
    return (
        f"standard errors, correlations and identifiability are not reported: the model's "
        f"output sensitivities at the fitted values diverge ({size}), so the model is locally "
        "unstable there or the integration step is too long for it; more substeps "
        "(--substeps) tell the two apart"
    )


def residual_correlation_time(r: np.ndarray, blocks: list[tuple[int, int]] | None = None) -> float:
    """Integrated autocorrelation time of the residuals ``r`` (rows, ≥ 1): how many
    consecutive residuals carry about one residual's worth of independent information.

    The fit's residuals are period means (a moving mean over one dither period) taken
    every ``decimate``-th sample and carry the model's misfit, which drifts over seconds;
    standard errors that take them for independent ones are far too small (session 65: on the
    default stand's fit the truth lay 7–163 of them from the fitted values). The
    autocorrelation is pooled over ``blocks`` (one per experiment: lags never cross from
    one experiment into the next), not centred (an offset that lasts a whole experiment
    is correlated error), and summed by Geyer's initial positive sequence (pairs of lags
    while their sum stays positive). It differs on purpose from discovery's
    ``integrated_time`` (centred per experiment, Sokal's window), which sizes that
    module's statistics: on the same rows of three of the default stand's fits it reads
    22–35 where this reads 49–99, the difference being the experiments' own offsets,
    which a standard error must count.

    Parameters
    ----------
    r : ndarray
        Residuals (bar).
    blocks : list of (int, int), optional
        ``(first row, number of rows)`` of each contiguous series in ``r``; default: one.

    Returns
    -------
    float
        ``τ = 1 + 2 Σ ρ_l`` in rows; 1 for independent residuals.
    """
    r = np.asarray(r, dtype=float)
    blocks = blocks or [(0, len(r))]
    acc = np.zeros(max((n for _, n in blocks), default=0))
    for row0, n in blocks:
        x = np.nan_to_num(r[row0 : row0 + n])
        if len(x) >= 2:
            acc[: len(x)] += lagged_sums(x)
    if not len(acc) or acc[0] <= 0:
        return 1.0
    rho = acc / acc[0]
    tau, k = -1.0, 0
    while 2 * k + 1 < len(rho) and (pair := rho[2 * k] + rho[2 * k + 1]) > 0:
        tau += 2.0 * pair
        k += 1
    return max(float(tau), 1.0)


def correlation_note(tau: float | None, uncertainty_note: str = "") -> str:
    """What the standard errors allow for, in words (``""`` when there is nothing to say:
    ``tau`` not reported, or no standard errors at all, ``uncertainty_note`` saying why).

    Parameters
    ----------
    tau : float or None
        The residuals' integrated autocorrelation time (consecutive residuals;
        :func:`residual_correlation_time`), NaN or None when not reported.
    uncertainty_note : str
        The fit's ``uncertainty_note`` (non-empty: its standard errors are not reported).
    """
    if uncertainty_note or tau is None or not math.isfinite(tau):
        return ""
    return (
        f"standard errors allow for the residuals' correlation over {tau:.3g} consecutive residuals"
    )


def identifiability(
    jz: np.ndarray, names: list[str], rel_se: np.ndarray
) -> tuple[list[float], list[str], list[dict]]:
    """SVD of the output sensitivities ``jz`` (residuals × scaled parameters), columns normalized.

    Returns the singular values, the names of unidentifiable parameters (large
    relative standard error, or dominating a direction whose singular value is
    below ``SV_RATIO_LIMIT`` of the largest) and, per weak direction, its loadings.
    """
    # Unit-norm columns: the SVD then measures collinearity; magnitude is judged by rel_se.
    norms = np.linalg.norm(jz, axis=0)
    _, sv, vt = np.linalg.svd(jz / np.where(norms > 0, norms, 1.0), full_matrices=False)
    weak = []
    bad = {n for n, r in zip(names, rel_se, strict=True) if not np.isfinite(r) or r > REL_SE_LIMIT}
    for s, v in zip(sv, vt, strict=True):
        if s < SV_RATIO_LIMIT * sv[0]:
            load = {n: float(c) for n, c in zip(names, v, strict=True) if abs(c) > 0.3}
            weak.append({"singular_value": float(s), "loadings": load})
            bad |= set(load)
    return [float(s) for s in sv], sorted(bad, key=names.index), weak


@dataclass
class ParameterUncertainty:
    """Standard errors and identifiability of the free parameters at a fit's values.

    Attributes
    ----------
    std_errors : dict
        Parameter name -> standard error (its unit; NaN when not reported).
    correlation : list of list
        Correlation matrix (order of the names; empty when not reported).
    singular_values : list of float
        Of the column-normalized sensitivities (empty when not reported).
    unidentifiable : list of str
        Parameters the data cannot determine.
    weak_directions : list of dict
        Near-null directions with their loadings.
    note : str
        Why nothing is reported (``""`` when it is; :func:`diverged_sensitivities`).
    correlation_time : float
        The residuals' integrated autocorrelation time (rows) the standard errors allow
        for (:func:`residual_correlation_time`; NaN when not reported).
    """

    std_errors: dict[str, float]
    correlation: list[list[float]]
    singular_values: list[float]
    unidentifiable: list[str]
    weak_directions: list[dict]
    note: str = ""
    correlation_time: float = math.nan


def parameter_uncertainty(
    jz: np.ndarray,
    r: np.ndarray,
    names: list[str],
    specs: dict,
    values,
    blocks: list[tuple[int, int]] | None = None,
) -> ParameterUncertainty:
    """Gauss–Newton standard errors and identifiability from the output sensitivities.

    The covariance is ``τ σ² (JᵀJ)⁺`` with ``σ²`` the residual variance (``r·r / dof``)
    and ``τ`` the residuals' integrated autocorrelation time
    (:func:`residual_correlation_time`: ``n / τ`` residuals' worth of independent
    information), in the solver's scaled coordinates, then mapped to engineering units (a
    log-scaled parameter's standard error is its value times that of its log). When the
    sensitivities diverged (:func:`diverged_sensitivities`) nothing is computed from
    them: the standard errors are NaN and the note says why.

    Parameters
    ----------
    jz : ndarray
        Residuals (bar) × scaled free parameters.
    r : ndarray
        Residuals (bar) at the fitted values.
    names : list of str
        Free parameters, in the column order of ``jz``.
    specs : dict
        Parameter name -> its specification (``transform``, ``scale``).
    values : mapping
        Fitted values (engineering units).
    blocks : list of (int, int), optional
        ``(first row, number of rows)`` of each experiment's residuals (default: one
        series).

    Returns
    -------
    ParameterUncertainty
    """
    note = diverged_sensitivities(jz)
    if note:  # a covariance from these would be noise (1e-40 "standard errors")
        return ParameterUncertainty(dict.fromkeys(names, math.nan), [], [], [], [], note)
    dof = max(len(r) - jz.shape[1], 1)
    sigma2 = float(np.dot(r, r)) / dof
    tau = residual_correlation_time(r, blocks)
    cov = tau * sigma2 * np.linalg.pinv(jz.T @ jz)
    sd_z = np.sqrt(np.clip(np.diag(cov), 0, None))
    se, rel = {}, []
    for k, n in enumerate(names):
        spec, v = specs[n], values[n]
        se[n] = float(abs(v if spec.transform == "log" else spec.scale) * sd_z[k])
        ref = abs(v) if spec.transform == "log" else max(abs(v), 0.01 * spec.scale)
        rel.append(se[n] / ref)
    d = np.where(sd_z > 0, sd_z, 1.0)
    sv, unid, weak = identifiability(jz, names, np.array(rel))
    return ParameterUncertainty(se, (cov / np.outer(d, d)).tolist(), sv, unid, weak, "", tau)


@dataclass
class FitResult:
    """What :class:`PhysicsFitter` found.

    Attributes
    ----------
    effects : list of str
        Effects switched on in the fitted model.
    values : dict
        Every parameter value (engineering units), fitted or fixed.
    units : dict
        Unit of every parameter.
    free : list of str
        Fitted parameters.
    std_errors : dict
        Standard error of each free parameter (its unit), from the Gauss–Newton
        Fisher information with the residual variance estimated from the fit, inflated
        by the residuals' correlation time (``residual_correlation_time``).
    correlation : list of list
        Correlation matrix of the free parameters (order of ``free``).
    singular_values : list of float
        Of the output sensitivities to the scaled free parameters.
    unidentifiable : list of str
        Free parameters the data cannot determine.
    weak_directions : list of dict
        Near-null directions of the sensitivities with their parameter loadings.
    per_experiment : dict
        ``name -> {"rmse_bar", "fit_pct"}`` of the dither-period-mean pressure.
    per_experiment_values : dict
        ``name -> {param: value}`` for per-experiment parameters.
    cost_history : list of float
        ½‖r‖² at each new iterate.
    status : str
        Solver status.
    success : bool
        Converged (or acceptable).
    iterations : int
        Solver iterations of the best start.
    wall_s : float
        Wall time of the fit (s).
    train : list of str
        Experiments fitted on.
    settings : dict
        The fit settings used.
    note : str
        What the model is when that is not the solver's best iterate, in words (empty
        otherwise; written to JSON only when not empty): a fit whose solver never got
        below its staged start keeps the staged start.
    uncertainty_note : str
        Why ``std_errors`` are NaN and ``correlation``, ``singular_values``,
        ``unidentifiable`` empty, in words (empty when they are reported; written to JSON
        only when not empty): the output sensitivities at the fitted values diverged
        (:func:`diverged_sensitivities`).
    residual_correlation_time : float
        Integrated autocorrelation time of the training residuals that ``std_errors``
        allow for, in consecutive residuals (the fit's rows: every ``decimate``-th sample,
        10 ms apart by default; :func:`residual_correlation_time`); NaN when not reported
        (and then not written to JSON).
    """

    effects: list[str]
    values: dict[str, float]
    units: dict[str, str]
    free: list[str]
    std_errors: dict[str, float]
    correlation: list[list[float]]
    singular_values: list[float]
    unidentifiable: list[str]
    weak_directions: list[dict]
    per_experiment: dict[str, dict[str, float]]
    per_experiment_values: dict[str, dict[str, float]]
    cost_history: list[float]
    status: str
    success: bool
    iterations: int
    wall_s: float
    train: list[str]
    settings: dict = field(default_factory=dict)
    note: str = ""
    uncertainty_note: str = ""
    residual_correlation_time: float = math.nan

    def __repr__(self) -> str:
        # the dataclass repr printed every value, the correlation matrix and the cost history
        return (
            f"FitResult(status={self.status!r}, success={self.success}, "
            f"effects={list(self.effects)!r}, free={list(self.free)!r}, "
            f"train={len(self.train)} experiment(s), iterations={self.iterations}, "
            f"wall_s={self.wall_s:.3g}; .table() lists the values)"
        )

    def model(self) -> CircuitModel:
        """The fitted model structure (base circuit + the effects)."""
        return CircuitModel().with_effects(*(make_effect(e) for e in self.effects))

    def params(self) -> ParameterSet:
        """The fitted values as a ParameterSet of :meth:`model`."""
        return self.model().params(**self.values)

    def table(self) -> str:
        """Free parameters with standard errors, as text."""
        lines = [f"{'parameter':18s} {'value':>12s} {'± std err':>12s}  unit"]
        for n in self.free:
            flag = "  (not identifiable)" if n in self.unidentifiable else ""
            lines.append(
                f"{n:18s} {self.values[n]:12.5g} {self.std_errors.get(n, math.nan):12.3g}  "
                f"{unit_shown(self.units[n])}{flag}"
            )
        if self.uncertainty_note:
            lines.append(f"({self.uncertainty_note})")
        if note := correlation_note(self.residual_correlation_time, self.uncertainty_note):
            lines.append(f"({note})")
        return "\n".join(lines)

    def to_json(self, path: str | Path | None = None) -> str:
        """JSON text (written to ``path`` when given, atomically)."""
        doc = asdict(self)
        for key in ("note", "uncertainty_note"):
            if not doc[key]:
                del doc[key]  # files of fits without one stay as they were
        if not math.isfinite(doc["residual_correlation_time"]):
            del doc["residual_correlation_time"]
        text = json.dumps(doc, indent=2, ensure_ascii=False, allow_nan=True)
        if path is not None:
            write_file_atomic(path, (text + "\n").encode("utf-8"), overwrite=True)
        return text

    @classmethod
    def from_json(cls, source: str | Path) -> FitResult:
        """Read what :meth:`to_json` wrote (a path or the JSON text).

        The content is checked before anything is built (:func:`check_fit_document`).

        Raises
        ------
        FitError
            If the file cannot be read or is not JSON.
        FitResultError
            (a FitError and a ModelError) Listing every problem of the content: missing,
            unknown or mistyped keys, unknown effects or parameter names, parameter values
            not finite or outside their bounds, units other than the model's.
        """
        text = str(source)
        name = "fit result (JSON text)"
        if not text.lstrip().startswith("{"):
            name = str(source)
            try:
                text = Path(source).read_text(encoding="utf-8")
            except (OSError, ValueError) as exc:
                raise FitError(f"cannot read fit result {source}: {exc}") from exc
        try:
            doc = json.loads(text)
        except (json.JSONDecodeError, RecursionError) as exc:
            raise FitError(f"not a clutchlab fit result: {name}: {exc}") from exc
        check_fit_document(doc, name)
        return cls(**doc)


def _is_real(value) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _list_of(kind, value) -> bool:
    return isinstance(value, list) and all(isinstance(v, kind) for v in value)


#: Type rule of every key of a fit-result document: a description and a test.
_FIELDS: dict[str, tuple[str, object]] = {
    "effects": ("a list of effect names", lambda v: _list_of(str, v)),
    "values": ("an object of numbers", lambda v: isinstance(v, dict)),
    "units": ("an object of unit names", lambda v: isinstance(v, dict)),
    "free": ("a list of parameter names", lambda v: _list_of(str, v)),
    "std_errors": ("an object of numbers", lambda v: isinstance(v, dict)),
    "correlation": ("a list of lists of numbers", lambda v: _list_of(list, v)),
    "singular_values": ("a list of numbers", lambda v: isinstance(v, list)),
    "unidentifiable": ("a list of parameter names", lambda v: _list_of(str, v)),
    "weak_directions": ("a list of objects", lambda v: _list_of(dict, v)),
    "per_experiment": ("an object of objects", lambda v: isinstance(v, dict)),
    "per_experiment_values": ("an object of objects", lambda v: isinstance(v, dict)),
    "cost_history": ("a list of numbers", lambda v: isinstance(v, list)),
    "status": ("a string", lambda v: isinstance(v, str)),
    "success": ("true or false", lambda v: isinstance(v, bool)),
    "iterations": ("an integer", lambda v: isinstance(v, int) and not isinstance(v, bool)),
    "wall_s": ("a number of seconds", _is_real),
    "train": ("a list of experiment names", lambda v: _list_of(str, v)),
    "settings": ("an object", lambda v: isinstance(v, dict)),
    "note": ("a string", lambda v: isinstance(v, str)),
    "uncertainty_note": ("a string", lambda v: isinstance(v, str)),
    "residual_correlation_time": ("a number of residuals", _is_real),
}
_OPTIONAL = ("settings", "note", "uncertainty_note", "residual_correlation_time")


def check_fit_document(doc, source: str = "fit result") -> None:
    """Check a parsed fit-result JSON; raise one error listing every problem.

    Parameters
    ----------
    doc : object
        What ``json.loads`` gave for the file.
    source : str
        The file named in the error.

    Raises
    ------
    FitResultError
        Listing every problem, each naming its key: missing, unknown or mistyped keys;
        unknown effects; unknown parameter names (in ``values``, ``units``, ``free``,
        ``std_errors``, ``unidentifiable``, ``per_experiment_values``); parameter values
        not finite or outside their bounds (engineering units); a fitted (``free``)
        parameter without a value; units other than the model's; numbers that are not
        numbers.
    """
    if not isinstance(doc, dict):
        raise FitResultError(
            f"{source}: not a clutchlab fit result (a JSON object is expected, got "
            f"{type(doc).__name__})"
        )
    if not any(k in _FIELDS for k in doc):
        keys = ", ".join(sorted(map(str, doc))[:8]) or "none"
        raise FitResultError(
            f"{source}: not a clutchlab fit result: it has none of the keys of one "
            f"({', '.join(k for k in _FIELDS if k not in _OPTIONAL)}); its keys: {keys}"
        )
    problems: list[str] = []
    unknown = sorted(str(k) for k in doc if k not in _FIELDS)
    if unknown:
        problems.append(f"unknown key(s) {', '.join(unknown)}")
    ok = {}
    for key, (what, test) in _FIELDS.items():
        if key not in doc:
            if key not in _OPTIONAL:
                problems.append(f"{key}: missing key")
        elif not test(doc[key]):
            problems.append(f"{key}: must be {what}, got {_short(doc[key])}")
        else:
            ok[key] = doc[key]
    for key in ("singular_values", "cost_history"):
        if key in ok and not all(_is_real(v) for v in ok[key]):
            problems.append(f"{key}: must be a list of numbers")
    if "correlation" in ok and not all(all(_is_real(x) for x in r) for r in ok["correlation"]):
        problems.append("correlation: must be a list of lists of numbers")
    specs = None
    if "effects" in ok:
        bad = [
            e for e in ok["effects"] if e.strip() not in EFFECTS and e.strip() not in FLEXIBLE_LAWS
        ]
        dupes = sorted({e for e in ok["effects"] if ok["effects"].count(e) > 1})
        if bad:
            known = ", ".join([*EFFECTS, *FLEXIBLE_LAWS])
            problems.append(f"effects: unknown effect(s) {bad!r}; known: {known}")
        if dupes:
            problems.append(f"effects: switched on twice: {', '.join(dupes)}")
        if not bad and not dupes:
            try:
                model = CircuitModel().with_effects(*(make_effect(e) for e in ok["effects"]))
                specs = {p.name: p for p in model.parameters}
            except ClutchlabError as exc:
                problems.append(f"effects: {exc}")
    if specs is not None:
        _check_values(ok.get("values", {}), specs, "values", problems)
        for exp, vals in ok.get("per_experiment_values", {}).items():
            where = f"per_experiment_values.{exp}"
            if isinstance(vals, dict):
                _check_values(vals, specs, where, problems)
            else:
                problems.append(f"{where}: must be an object of numbers, got {_short(vals)}")
        for name, unit in ok.get("units", {}).items():
            if name not in specs:
                problems.append(f"units.{name}: unknown parameter")
            elif unit != specs[name].unit:
                problems.append(
                    f"units.{name}: {unit!r}, but the model's unit is {specs[name].unit!r}"
                )
        for key in ("free", "unidentifiable"):
            bad = [n for n in ok.get(key, []) if n not in specs]
            if bad:
                problems.append(f"{key}: unknown parameter(s) {bad!r}")
        per_exp = [v for v in ok.get("per_experiment_values", {}).values() if isinstance(v, dict)]
        lost = [
            n
            for n in ok.get("free", [])
            if n in specs
            and n not in ok.get("values", {})
            and not (per_exp and all(n in v for v in per_exp))
        ]
        if lost and "values" in ok:  # the datasheet value would stand in for the fitted one
            problems.append(f"values: no value for the fitted parameter(s) {lost!r}")
        for name, se in ok.get("std_errors", {}).items():
            if name not in specs:
                problems.append(f"std_errors.{name}: unknown parameter")
            elif not _is_real(se) or se < 0:  # NaN / inf: a parameter the data do not fix
                problems.append(f"std_errors.{name}: must be a number >= 0, got {_short(se)}")
    for exp, metrics in ok.get("per_experiment", {}).items():
        if not isinstance(metrics, dict) or not all(_is_real(v) for v in metrics.values()):
            problems.append(f"per_experiment.{exp}: must be an object of numbers")
    if problems:
        raise FitResultError(f"{source}: not a clutchlab fit result, or a damaged one", problems)


def _check_values(values: dict, specs: dict, where: str, problems: list[str]) -> None:
    """Parameter values: known names, finite numbers inside the bounds."""
    for name, value in values.items():
        if name not in specs:
            problems.append(f"{where}.{name}: unknown parameter")
        elif not _is_real(value):
            problems.append(f"{where}.{name}: must be a number, got {_short(value)}")
        else:
            try:
                msg = specs[name].check(float(value))
            except OverflowError:  # an integer beyond the float range
                msg = f"{name} = {_short(value)} is not finite"
            if msg:
                problems.append(f"{where}.{name}: {msg}")


def _short(value) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."
