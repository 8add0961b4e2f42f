"""Typed settings of the physics fit."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import MISSING, dataclass, field, fields
from typing import Literal

from ...budgets import FIT_BUDGET_S
from ...errors import FitError
from ..settings import MAX_SETTLE_S, is_finite_real, is_integer

__all__ = ["DEFAULT_FREE", "FIT_BUDGET_S", "FitSettings"]

#: Parameters of the base circuit freed by default: the ones a set of current
#: ramps excites — VFS force curve and preload (gain, threshold), regulator spring
#: offset and friction (offset, hysteresis), the VFS accumulator orifice (rate-
#: dependent lag), the latch preload and spring (latch-on / latch-off currents).
DEFAULT_FREE: tuple[str, ...] = (
    "vfs_K_m",
    "vfs_i_knee",
    "vfs_F_pre",
    "reg_F0",
    "reg_F_c",
    "vfs_d_orf",
    "latch_F0",
    "latch_k",
)


#: IPOPT options a FitSettings field sets (each stage derives its own value from the field).
_OWNED_IPOPT_OPTIONS = {"max_iter": "max_iter", "max_wall_time": "time_limit_s", "tol": "tol"}


@dataclass(frozen=True)
class FitSettings:
    """How :class:`PhysicsFitter` fits.

    Attributes
    ----------
    free : tuple of str or None
        Parameters to estimate. ``None``: :data:`DEFAULT_FREE` plus the fit
        parameters of every switched-on effect. One name alone (a string) is one parameter.
    per_experiment : tuple of str
        Free parameters estimated separately for each experiment (the rest are shared).
    bounds : dict
        Bound overrides ``name -> (lower, upper)`` in the parameter's unit, for free
        parameters only.
    method : {"single_shooting", "multiple_shooting"}
        Single shooting (default): one simulation per experiment from its settled
        state. Multiple shooting: experiments cut into segments of ``segment_s``
        whose initial states are decision variables tied by continuity
        constraints. Measured on this circuit (dissipative, lags < 0.1 s): both
        reach the same optimum in about the same number of iterations, and multiple
        shooting costs twice as much per iteration (its sensitivities carry the
        nx initial-state directions besides the parameters), which would take the
        full training fit past its 120 s budget; it remains the choice for long,
        poorly initialized or unstable experiments.
    segment_s : float
        Segment length (s) for multiple shooting.
    substeps : int
        ROS2 steps per sample during the fit (scored models use the simulator's
        default); the effect on the optimum is measured in ``benchmarks/bench_fit.py``.
    drive : {"auto", "command", "measured"}
        Coil excitation during the fit (see :class:`SimulationSettings`): the measured
        current when present (``auto``), or the command through the current loop.
    objective : {"period_mean", "raw"}
        Residual of the dither-period-averaged pressure (default) or the raw one.
    decimate : int
        Keep every ``decimate``-th residual (the period mean is smooth over a
        dither period, so little information is lost; measured in the benchmark).
    fit_rate_Hz : float or None
        Sample rate of the fit, Hz: training experiments logged faster than 1.5 × this are
        resampled onto a grid at this rate before the fit
        (:func:`~clutchlab.physics.fit.rate.at_fit_rate`), so that the fit's cost and its
        sample budgets do not grow with the logger's rate; the per-experiment metrics are
        then those of the resampled experiments. None (default) fits every sample: as a
        default, 1000 Hz failed its landing rule on one of two zoo datasets (BENCHMARKS,
        "Data logged faster than 1 kHz").
    snap_rate_bar_s, snap_guard_s : float
        Residuals within ``snap_guard_s`` (s) of a latch snap — where the measured
        period-mean pressure moves faster than ``snap_rate_bar_s`` (bar/s; the
        regulated ramps stay below ~10 bar/s) — are left out of the objective: there
        the error is the snap's timing, resolved on the sample grid, which makes the
        cost non-smooth at that scale. The latch currents are still fitted by the
        samples around the guard. Default 0 (every residual kept): measured on the
        recovery test, a 20 ms guard biased the gain (0.3 %, 11 standard errors)
        and hid the pilot-volume non-identifiability, for no fewer iterations on the
        stand data.
    train_ramps : tuple of str
        Ramp labels fitted on; the others (the test ramp) are never seen. One label alone
        (a string) is one ramp.
    max_iter : int
        IPOPT iteration limit.
    prefit_samples : int or None
        When the training data hold more samples, first fit on a subset of about
        this many (experiments round-robin over the ramp labels), then refine on
        all of them for at most ``refine_max_iter`` iterations. None or 0: one stage.
    refine_max_iter : int
        Iteration limit of the refinement on all training experiments.
    prefit_obj_change_tol : float
        The pre-fit stops once the cost changes by less than this fraction on two
        successive iterations and the scaled optimality error is below 0.1 (IPOPT
        ``acceptable_obj_change_tol``, ``acceptable_tol``): its optimum only starts
        the refinement, so a tight pre-fit tolerance buys nothing. It also stops, with
        status ``Cost_Plateau``, once its cost has moved by less than this fraction
        over its last ``prefit_plateau_iter`` iterations (a cost with kinks keeps a large
        optimality error where it no longer falls); the refinement follows either way.
    prefit_plateau_iter : int
        Iterations of that plateau test (0: IPOPT's stop only).
    plateau_iter : int
        The same test on every solve of a fit with these settings (the pre-fit stage
        gets ``prefit_plateau_iter``); 0, the default, leaves the stop to IPOPT.
    tol : float
        IPOPT convergence tolerance.
    time_limit_s : float
        Wall-clock limit of the whole fit (s, finite and > 0): staged start, solver and result; the
        solver stops at 88 % of it (the rest is kept for the result's per-experiment
        errors and uncertainty pass), starts no iteration that the previous ones say it
        cannot finish by then, and skips a refinement that cannot take its first
        Jacobian; the best iterate is kept when a limit is reached.
    multistart : int
        Extra starts drawn (Latin hypercube) inside the bounds, besides the defaults.
    seed : int
        Seed of the multistart draws.
    settle_s : float
        Settling time (s) before each experiment, at its first inputs; 0 to 60 s
        (:data:`~clutchlab.physics.settings.MAX_SETTLE_S`).
    min_current_span_mA, min_pressure_span_bar : float
        An experiment whose current or pressure spans less carries no excitation.
    progress : bool
        Show a live progress bar (iteration, cost).
    workers : int
        Processes that simulate experiments in parallel (1: in this process).
    ipopt_options : dict
        Extra IPOPT options. Not ``max_iter``, ``max_wall_time`` nor ``tol``: those are
        ``max_iter``, ``time_limit_s`` and ``tol`` here (refused, naming the field).
    staged_start : bool
        Start from the data before the full fit (:mod:`~clutchlab.physics.fit.staged`):
        the static characteristic on the quasi-static rising branch, then the latch
        thresholds at the measured latch currents. Used only when the fit starts from the
        datasheet values (no user start). Default True.
    latch_law : {"auto", "datasheet"}
        ``auto``: when the staged start finds the training data's latch thresholds closer
        together than the datasheet latch's area ratio allows, the fit uses the
        ``latch_free_thresholds`` law instead (same parameter count, no tie) and says
        so; ``datasheet``: keep the model's latch as given.
    regulator_lag : {"auto", "off"}
        ``auto`` (default): when the staged start finds the training data's regulated band
        widening with ramp rate more, relative to the latch's delay, than the model's one
        pilot lag can give (:func:`~clutchlab.physics.fit.staged.lag_signature`), the
        regulated branch lags through a path the latch does not see: the fit adds the
        ``reg_pilot_lag`` law (one parameter, its time constant), then chooses the latch
        port on the fast training ramps (:func:`~clutchlab.physics.fit.staged.
        latch_port_structure`: the datasheet feedback exhaust, or ``latch_line_select``),
        and says so; ``off``: never. The default stand's data do not ask for it (its
        fit is unchanged). Session 45, held-back 5 s + 20 s ramps of the four zoo plants
        (seeds 0 and 1, trained on fast + slow): the two laws lowered the physics RMSE on
        all 8 datasets (BENCHMARKS, "a latch that switches the clutch port"); before, with
        ``reg_pilot_lag`` alone, ``auto`` raised it on some (sessions 20 and 34), and was
        off by default.
    latch_band : {"auto", "band", "off"}
        ``auto`` (default): when the quasi-static training experiments' latch snaps move
        with the dither amplitude and frequency, or with the logged line pressure, more
        than the latch thresholds alone can follow (leave-one-experiment-out, on the
        staged start's model and again on the fitted one;
        :mod:`~clutchlab.physics.fit.latch_band`), the fit adds ``latch_dither_band``
        and / or ``latch_line_threshold`` after the solver, held at the values the snaps
        give with the thresholds matched, and keeps them only when they lower the training
        RMS (logged either way); the solver leaves the stage ``BAND_RESERVE_S`` of its
        time. Where ``latch_dither_band`` is added, the latch rate stage then tests the
        faster training ramps' snaps the same way and may add ``latch_rate_band``
        (:mod:`~clutchlab.physics.fit.latch_rate`); where neither band law is added, the
        latch lag stage tests the slow and fastest ramps' snaps for ``latch_on_lag``
        (:mod:`~clutchlab.physics.fit.latch_lag`). ``band``: the dither band law only (the
        default before session 59; the rate and latch lag stages still run). ``off``:
        never. Needs the staged start; not with ``free``.
    static_max_iter : int
        Iteration limit of the staged start's static stage.
    static_time_fraction : float
        Share of ``time_limit_s`` the static stage may use.
    strict : bool
        A fit stopped at a limit (iterations, wall time) raises ``FitError`` (with the best
        iterate in ``exc.result``). Default False: the best iterate *is* the model, marked
        not converged (``result_.success`` False, its status) with a ``FitWarning``; only a
        fit that did not improve on its start raises (a staged start that improved on the
        datasheet values counts: it is then the model, ``result_.note`` says so).

    Raises
    ------
    FitError
        At construction, listing every invalid setting: a count that is not an integer in
        its range (``substeps`` 1..16; ``decimate``, ``max_iter``, ``refine_max_iter``,
        ``workers``, ``static_max_iter`` ≥ 1; ``multistart``, ``prefit_samples``, the
        plateau counts ≥ 0), a time, tolerance or span that is not finite or out of range,
        a name list holding something other than names, a bound that is not two finite
        numbers.
    """

    free: tuple[str, ...] | None = None
    per_experiment: tuple[str, ...] = ()
    bounds: dict[str, tuple[float, float]] = field(default_factory=dict)
    method: Literal["multiple_shooting", "single_shooting"] = "single_shooting"
    segment_s: float = 20.0
    substeps: int = 2
    drive: Literal["auto", "command", "measured"] = "auto"
    objective: Literal["period_mean", "raw"] = "period_mean"
    decimate: int = 10
    fit_rate_Hz: float | None = None
    snap_rate_bar_s: float = 60.0
    snap_guard_s: float = 0.0
    train_ramps: tuple[str, ...] = ("fast", "slow")
    max_iter: int = 50
    prefit_samples: int | None = 160_000
    refine_max_iter: int = 3
    prefit_obj_change_tol: float = 1e-3
    prefit_plateau_iter: int = 10
    plateau_iter: int = 0
    tol: float = 1e-6
    time_limit_s: float = 900.0
    multistart: int = 0
    seed: int = 0
    settle_s: float = 0.5
    min_current_span_mA: float = 50.0
    min_pressure_span_bar: float = 0.2
    progress: bool = True
    workers: int = 2
    ipopt_options: dict = field(default_factory=dict)
    staged_start: bool = True
    latch_law: Literal["auto", "datasheet"] = "auto"
    regulator_lag: Literal["auto", "off"] = "auto"
    latch_band: Literal["auto", "band", "off"] = "auto"
    static_max_iter: int = 15
    static_time_fraction: float = 0.2
    strict: bool = False

    def __repr__(self) -> str:
        # thirty-odd fields: name the ones that differ from their defaults
        changed = []
        for f in fields(self):
            default = f.default_factory() if f.default is MISSING else f.default
            value = getattr(self, f.name)
            if value != default:
                changed.append(f"{f.name}={value!r}")
        return f"FitSettings({', '.join(changed)})"

    def __post_init__(self) -> None:
        problems = []
        # names: one name alone is a one-name tuple, not a sequence of its characters
        for name, optional in (("free", True), ("per_experiment", False), ("train_ramps", False)):
            value = getattr(self, name)
            if value is None and optional:
                continue
            if isinstance(value, str):
                value = (value,)
            try:
                value = tuple(value)
            except TypeError:
                problems.append(f"{name} must be a name or a sequence of names, not {value!r}")
                continue
            bad = [v for v in value if not (isinstance(v, str) and v)]
            if bad:
                problems.append(f"{name}: {', '.join(map(repr, bad))} not a name (a string)")
            object.__setattr__(self, name, value)
        problems += _bounds_problems(self.bounds)
        if not isinstance(self.ipopt_options, dict):
            problems.append(f"ipopt_options must be a dict, not {self.ipopt_options!r}")
        else:
            owned = [k for k in self.ipopt_options if k in _OWNED_IPOPT_OPTIONS]
            problems += [
                f"ipopt_options[{k!r}] is set by FitSettings.{_OWNED_IPOPT_OPTIONS[k]} (each "
                "stage of the fit derives its own from it; the IPOPT option would silently "
                f"override that): set {_OWNED_IPOPT_OPTIONS[k]} instead"
                for k in owned
            ]
        if self.method not in ("multiple_shooting", "single_shooting"):
            problems.append(f"method {self.method!r} is not multiple_shooting or single_shooting")
        if self.objective not in ("period_mean", "raw"):
            problems.append(f"objective {self.objective!r} is not period_mean or raw")
        if self.drive not in ("auto", "command", "measured"):
            problems.append(f"drive {self.drive!r} is not auto, command or measured")
        # integers: (name, smallest, largest or None)
        for name, lo, hi in (
            ("substeps", 1, 16),
            ("decimate", 1, None),
            ("max_iter", 1, None),
            ("refine_max_iter", 1, None),
            ("multistart", 0, None),
            ("workers", 1, None),
            ("prefit_plateau_iter", 0, None),
            ("plateau_iter", 0, None),
            ("static_max_iter", 1, None),
        ):
            value = getattr(self, name)
            if not is_integer(value) or value < lo or (hi is not None and value > hi):
                what = f"{lo}..{hi}" if hi is not None else f"≥ {lo}"
                problems.append(f"{name} must be {what} (an integer), not {value!r}")
        if not is_integer(self.seed):
            problems.append(f"seed must be an integer, not {self.seed!r}")
        if self.prefit_samples is not None and (
            not is_integer(self.prefit_samples) or self.prefit_samples < 0
        ):
            problems.append(
                "prefit_samples must be None or ≥ 0 (an integer; 0 or None: no pre-fit), "
                f"not {self.prefit_samples!r}"
            )
        # finite reals: (name, condition, what it must be)
        for name, ok, what in (
            ("segment_s", lambda v: v > 0, "> 0 s"),
            ("time_limit_s", lambda v: v > 0, "> 0 s"),
            ("tol", lambda v: v > 0, "> 0"),
            ("settle_s", lambda v: 0 <= v <= MAX_SETTLE_S, f"in 0..{MAX_SETTLE_S:g} s"),
            ("snap_rate_bar_s", lambda v: v > 0, "> 0 bar/s"),
            ("snap_guard_s", lambda v: v >= 0, "≥ 0 s"),
            ("min_current_span_mA", lambda v: v >= 0, "≥ 0 mA"),
            ("min_pressure_span_bar", lambda v: v >= 0, "≥ 0 bar"),
            ("prefit_obj_change_tol", lambda v: v > 0, "> 0"),
            ("static_time_fraction", lambda v: 0 < v < 1, "in (0, 1)"),
        ):
            value = getattr(self, name)
            if not is_finite_real(value) or not ok(value):
                problems.append(f"{name} must be {what} (a finite number), not {value!r}")
        if self.fit_rate_Hz is not None and not (
            is_finite_real(self.fit_rate_Hz) and self.fit_rate_Hz > 0
        ):
            problems.append(f"fit_rate_Hz must be > 0 Hz or None, not {self.fit_rate_Hz!r}")
        if self.latch_law not in ("auto", "datasheet"):
            problems.append(f"latch_law {self.latch_law!r} is not auto or datasheet")
        if self.regulator_lag not in ("auto", "off"):
            problems.append(f"regulator_lag {self.regulator_lag!r} is not auto or off")
        if self.latch_band not in ("auto", "band", "off"):
            problems.append(f"latch_band {self.latch_band!r} is not auto, band or off")
        if problems:
            raise FitError("invalid fit settings: " + "; ".join(problems))


def _bounds_problems(bounds) -> list[str]:
    """Every problem of ``FitSettings.bounds``: not a mapping ``name -> (lower, upper)`` of
    finite numbers (that lower < upper within the physical range is checked at the fit)."""
    if not isinstance(bounds, Mapping):
        return [f"bounds must be a dict name -> (lower, upper), not {bounds!r:.60}"]
    problems = []
    for name, pair in bounds.items():
        ok = (
            isinstance(pair, Sequence)
            and not isinstance(pair, str)
            and len(pair) == 2
            and all(is_finite_real(v) for v in pair)
        )
        if not ok:
            problems.append(
                f"bounds[{name!r}] must be (lower, upper), two finite numbers in the "
                f"parameter's unit, not {pair!r:.60}"
            )
    return problems
