"""FMU programs of learned models: GP mean and std, latch decision, causal dI/dt, hybrid.

The learned models live in :mod:`clutchlab.residual_ml`, a layer above this one, so they
reach the exporter as plain arrays: a :class:`GPSpec` per GP, a :class:`DecisionSpec` for the
latch classifier, a :class:`DidtSpec` for the causal dI/dt and direction features.
:func:`ml_program` turns them into an :class:`~clutchlab.physics.fmu.program.FmuProgram` —
standalone, or on top of a physics program (hybrid: physics pressure + residual GP).

The causal dI/dt and direction are defined on samples 1 ms apart (``DidtSpec.sample_s``, the
rate the feature builder computes them at on 1 kHz data), and so is the lagged current
(``LagSpec.sample_s``). The FMU resamples its current input to that rate by time, whatever
the communication step: a sample clock in the state puts the input's value at each instant
``t₀ + k · sample_s`` into the slope buffer and the lag (inputs linear over a step, with the
derivative the master sets; held otherwise); between instants the slope, direction and lag
are those of the newest sample. A communication step longer than ``sample_s`` is split into
internal steps of at most it (:attr:`FmuProgram.max_step_s`).

Per step the FMU evaluates the features at the step's end, the decision (> 0: latched,
then only the latched GP is evaluated) and the GP: ``n·d`` kernel terms for the mean and,
for the standard deviation (``with_std``), ``m·d`` kernel terms on the GP's std points and a
triangular ``m × m`` product (m ≤ 300 by default: ``LocalGPRegressor.max_std_points``).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ...data import LINE_PRESSURE_BAR
from ...data.demodulate import NO_DITHER_DIDT_HZ
from ...errors import ModelError
from .physics import FMU_INPUTS, input_range
from .program import FmuProgram, FmuVariable

__all__ = ["ML_FEATURES", "DecisionSpec", "DidtSpec", "GPSpec", "LagSpec", "ml_program"]

#: Features an exported ML model may use, with their units. ``current_lag_mA``,
#: ``didt_causal_mA_s`` and ``direction_causal`` are computed as the offline feature builder
#: computes them (``first_order_lag``, :func:`clutchlab.data.causal_didt`,
#: ``direction_of_travel``); ``physics_bar`` is the physics program's clutch pressure at the
#: step's end (not a dither-period mean).
ML_FEATURES: dict[str, str] = {
    "current_mA": "mA",
    "current_lag_mA": "mA",
    "dither_amp_mA": "mA",
    "dither_freq_Hz": "Hz",
    "didt_causal_mA_s": "mA/s",
    "direction_causal": "1",
    "physics_bar": "bar",
}
_SLOPE_FEATURES = ("didt_causal_mA_s", "direction_causal")


class _Constants:
    """The arrays of a program: small ones inline in the C code, large ones as inputs.

    Calling it with an array returns a CasADi matrix of the array's shape (1-D arrays as
    columns): a ``DM`` up to ``inline_limit`` elements, else an ``MX`` symbol that becomes
    a trailing input of every function (the same symbol for the same array).
    """

    def __init__(self, inline_limit: int = 4096) -> None:
        self.inline_limit = inline_limit
        self.arrays: list[np.ndarray] = []
        self.symbols: list[ca.MX] = []
        self._seen: dict[int, ca.MX] = {}

    def __call__(self, array) -> ca.DM | ca.MX:
        arr = np.asarray(array, dtype=float)
        arr = arr.reshape(-1, 1) if arr.ndim == 1 else arr
        if arr.size <= self.inline_limit:
            return ca.DM(arr)
        key = id(array)
        if key not in self._seen:
            sym = ca.MX.sym(f"c{len(self.symbols)}", *arr.shape)
            self.arrays.append(arr)
            self.symbols.append(sym)
            self._seen[key] = sym
        return self._seen[key]


_INLINE = _Constants(inline_limit=np.iinfo(np.int64).max)


def _number_problems(spec, finite=(), positive=(), positive_or_inf=()) -> list[str]:
    """The fields of ``spec`` that are not finite numbers (``finite``), not finite and > 0
    (``positive``) or not > 0 (``positive_or_inf``); None fields are skipped. An FMU built
    from them would compute NaN from its first step."""
    problems = []
    for names, test, what in (
        (finite, np.isfinite, "finite"),
        (positive, lambda a: np.isfinite(a) & (a > 0), "finite and > 0"),
        (positive_or_inf, lambda a: a > 0, "> 0"),
    ):
        for name in names:
            value = getattr(spec, name)
            if value is None:
                continue
            try:
                arr = np.asarray(value, dtype=float)
            except (TypeError, ValueError):
                problems.append(f"{name} must hold numbers")
                continue
            bad = int(np.count_nonzero(~test(arr)))
            if bad:
                problems.append(f"{name} must be {what} ({bad} value(s) are not)")
    return problems


@dataclass(frozen=True)
class GPSpec:
    """A fitted GP as arrays (the prediction of ``LocalGPRegressor``).

    ``mean(x) = y_mean + Σ_i weights_i · κ(r_i²)``, ``r_i² = Σ_j ((z_j − points_ij) /
    length_scales_j)²``, ``z = (x − x_mean) / x_scale``; ``κ(r²) = (1 + r²/2α)^(−α)``
    (``"rq"``) or ``exp(−r²/2)`` (``"rbf"``). Standard deviation (latent, noise excluded):
    ``y_scale · sqrt(max(s² − vᵀv, 0))``, ``v = L⁻¹ k``, ``k_i = s² κ(r_i²)`` with ``r_i``
    taken to ``std_points`` (default ``points``), ``s² = signal_var``, ``L`` the Cholesky
    factor of the std GP's kernel matrix (noise included).

    ``LocalGPRegressor`` computes its std from a GP on coarser bins than its mean (at most
    ``max_std_points``, 300 by default), so that the std costs m²/2 multiply-adds per step
    (the lower triangle of ``L⁻¹``) instead of n² and fits a 1 kHz step; the FMU evaluates
    the same formula on the same bins as the in-process model.

    Attributes
    ----------
    kernel : {"rq", "rbf"}
    x_mean, x_scale : ndarray (d,)
        Standardization of the features (feature units).
    length_scales : ndarray (d,)
        Length scales in standardized units.
    alpha : float
        Scale mixture α of the RQ kernel (ignored for RBF).
    points : ndarray (n, d)
        Training (bin) points of the mean, standardized.
    weights : ndarray (n,)
        ``K⁻¹y · s² · y_scale``: mean weights in target units (bar).
    y_mean : float
        Target offset (bar).
    signal_var : float
        s² in normalized target units (for the std).
    y_scale : float
        Target scale (bar).
    l_inv : ndarray (m, m) or None
        ``L⁻¹``, lower triangular, normalized units (its upper triangle is ignored); None:
        no std output.
    std_points : ndarray (m, d) or None
        Bin points of the std's GP, standardized; None: ``points``.
    noise_var : float
        Observation noise variance (bar²) added under the square root of the std: 0 for
        the latent std of a ``LocalGPRegressor``, the GP's ``noise_var_`` for the trace
        estimators' predictive std of a measured dither-period mean.
    """

    kernel: str
    x_mean: np.ndarray
    x_scale: np.ndarray
    length_scales: np.ndarray
    alpha: float
    points: np.ndarray
    weights: np.ndarray
    y_mean: float
    signal_var: float = 1.0
    y_scale: float = 1.0
    l_inv: np.ndarray | None = None
    std_points: np.ndarray | None = None
    noise_var: float = 0.0

    def __post_init__(self) -> None:
        n, d = np.shape(self.points)
        problems = []
        if self.kernel not in ("rq", "rbf"):
            problems.append(f"kernel {self.kernel!r} is not 'rq' or 'rbf'")
        for name in ("x_mean", "x_scale", "length_scales"):
            if np.shape(getattr(self, name)) != (d,):
                problems.append(f"{name} must have shape ({d},)")
        if np.shape(self.weights) != (n,):
            problems.append(f"weights must have shape ({n},)")
        m = n
        if self.std_points is not None:
            m = np.shape(self.std_points)[0]
            if np.shape(self.std_points) != (m, d):
                problems.append(f"std_points must have shape (m, {d})")
        if not (np.isfinite(self.noise_var) and self.noise_var >= 0):
            problems.append(f"noise_var must be finite and ≥ 0, got {self.noise_var!r}")
        if self.l_inv is not None and np.shape(self.l_inv) != (m, m):
            problems.append(f"l_inv must have shape ({m}, {m}) (one row per std point)")
        problems += _number_problems(
            self,
            finite=("x_mean", "points", "weights", "y_mean", "l_inv", "std_points"),
            positive=("x_scale", "length_scales", "alpha", "signal_var", "y_scale"),
        )
        if problems:
            raise ModelError("invalid GPSpec: " + "; ".join(problems))

    @property
    def n_features(self) -> int:
        """Number of input features d."""
        return int(np.shape(self.points)[1])

    def _profile(self, x: ca.MX, const: _Constants, scaled_points: np.ndarray) -> ca.MX:
        """Kernel profile κ(r_i²) of every point (1 × n), a serial map (a loop in C).

        ``scaled_points`` (d × n) are the points divided by the length scales
        (:attr:`_scaled`), so that a step divides the d features once, not n·d times. The
        RQ profile is ``exp(−α log(1 + r²/2α))``: ``log(1 + u)`` instead of ``log1p(u)``
        costs a third less, and its absolute error (≤ 1 ulp of 1 + u) moves κ by a
        relative ≤ α·2⁻⁵², far below the double rounding of the mean's sum."""
        d = self.n_features
        z = ((x - const(self.x_mean).T) / const(self.x_scale).T).T / ca.DM(self.length_scales)
        zs, pt = ca.SX.sym("z", d), ca.SX.sym("pt", d)
        r2 = ca.sumsqr(zs - pt)
        if self.kernel == "rbf":
            prof = ca.exp(-0.5 * r2)
        else:
            prof = ca.exp(-self.alpha * ca.log(1.0 + r2 * (0.5 / self.alpha)))
        kern = ca.Function("kernel", [zs, pt], [prof])
        n = scaled_points.shape[1]
        return kern.map(n, "serial")(z, const(scaled_points))

    @functools.cached_property
    def _scaled(self) -> tuple[np.ndarray, np.ndarray | None]:
        """The mean's and the std's points divided by the length scales, d × n (one array
        object each, so that a program holds each once)."""
        ls = np.asarray(self.length_scales, dtype=float)[:, None]
        pts = np.ascontiguousarray(np.asarray(self.points, dtype=float).T / ls)
        std = self.std_points
        return pts, None if std is None else np.ascontiguousarray(np.asarray(std).T / ls)

    @functools.cached_property
    def _l_inv_packed(self) -> np.ndarray:
        """Lower triangle of ``l_inv``, column by column (CasADi's column-major nonzeros).

        The sparse product compiles to a column-by-column multiply-add, which pipelines; a
        dense m × m product compiles to a row-by-row dot product, one long chain of
        dependent additions per row, and measured slower despite needing no index
        (BENCHMARKS, FMU step time)."""
        li = np.asarray(self.l_inv, dtype=float)
        return np.concatenate([li[j:, j] for j in range(li.shape[0])])

    def mean(self, x: ca.MX, const: _Constants = _INLINE) -> ca.MX:
        """Predictive mean (bar) at the row vector of features ``x`` (1 × d)."""
        return self.mean_std(x, const, False)[0]

    def std(self, x: ca.MX, const: _Constants = _INLINE) -> ca.MX:
        """Predictive standard deviation (bar) at ``x``; requires ``l_inv``."""
        return self.mean_std(x, const, True)[1]

    def mean_std(
        self, x: ca.MX, const: _Constants = _INLINE, with_std: bool = True
    ) -> tuple[ca.MX, ca.MX | None]:
        """Predictive mean and standard deviation (bar) at ``x``.

        Raises
        ------
        ModelError
            If ``with_std`` and the spec has no ``l_inv``.
        """
        if with_std and self.l_inv is None:
            raise ModelError("this GPSpec has no l_inv: no standard deviation")
        points, std_points = self._scaled
        prof = self._profile(x, const, points)
        mean = self.y_mean + ca.mtimes(prof, const(self.weights))
        if not with_std:
            return mean, None
        if std_points is not None:
            prof = self._profile(x, const, std_points)
        m = prof.shape[1]
        packed = const(self._l_inv_packed)  # the same array object: one constant per GP
        lower = ca.Sparsity.lower(m)
        l_inv = ca.MX(ca.DM(lower, packed)) if isinstance(packed, ca.DM) else ca.MX(lower, packed)
        v = ca.mtimes(l_inv, self.signal_var * prof.T)
        q = ca.sumsqr(v)
        latent = self.y_scale**2 * ca.fmax(self.signal_var - q, 0.0)
        return mean, ca.sqrt(latent + self.noise_var)


@dataclass(frozen=True)
class DecisionSpec:
    """A latch classifier's decision function (> 0: latched) on standardized features.

    ``kind="rbf"``: ``Σ_i coef_i exp(−γ |z − support_i|²) + intercept``; ``kind="linear"``:
    ``weights · z + intercept``; ``z = (x[columns] − mean) / scale`` (``columns``: the
    features the classifier uses, all when None). ``kind="event"``: the latch-event law of
    :class:`~clutchlab.residual_ml.latch_event.EventDecision` on ``x[columns]``, with its
    ``event_columns`` (current, dI/dt, direction, dither amplitude, dither frequency; −1:
    absent) and coefficients ``event_on`` / ``event_off`` (``mean``, ``scale`` and
    ``intercept`` unused). ``kind="local_event"``: the local law of
    :class:`~clutchlab.residual_ml.latch_local.LocalEventDecision` with the same
    ``event_columns``, its ``(n, 6)`` events in ``event_on`` / ``event_off`` (current,
    dI/dt, dither amplitude and frequency, and the within-setting deviations of current
    and dI/dt, :func:`~clutchlab.residual_ml.latch_local.within_setting`), the amplitude
    and frequency scales in ``event_scale``, the bandwidth in ``gamma`` and the slope
    prior's bandwidth and weight in ``event_slope``; ``event_line`` ``(β, p̄)`` (mA/bar,
    bar) when the law follows line pressure (the current is taken as ``I − β (p − p̄)``);
    ``event_censored`` ``(m, 3)``, the never-latched training experiments (peak current mA,
    amplitude mA, frequency Hz; :func:`~clutchlab.residual_ml.censored_share`).
    """

    kind: str
    mean: np.ndarray
    scale: np.ndarray
    intercept: float
    support: np.ndarray | None = None
    coef: np.ndarray | None = None
    gamma: float = 1.0
    weights: np.ndarray | None = None
    columns: tuple[int, ...] | None = None
    event_columns: tuple[int, ...] | None = None
    event_on: np.ndarray | None = None
    event_off: np.ndarray | None = None
    event_scale: np.ndarray | None = None
    event_slope: np.ndarray | None = None
    event_line: np.ndarray | None = None
    event_censored: np.ndarray | None = None

    def __post_init__(self) -> None:
        ok = (
            (self.kind == "rbf" and self.support is not None and self.coef is not None)
            or (self.kind == "linear" and self.weights is not None)
            or (
                self.kind == "event"
                and self.event_columns is not None
                and len(self.event_columns) == 5
                and self.event_on is not None
                and self.event_off is not None
            )
            or (
                self.kind == "local_event"
                and self.event_columns is not None
                and len(self.event_columns) == 5
                and self.event_on is not None
                and self.event_off is not None
                and self.event_scale is not None
                and self.event_slope is not None
            )
        )
        if not ok:
            raise ModelError(
                "invalid DecisionSpec: kind 'rbf' needs support and coef, 'linear' needs "
                "weights, 'event' needs event_columns (5), event_on and event_off, "
                "'local_event' also event_scale and event_slope"
            )
        problems = _number_problems(
            self,
            finite=(
                "mean",
                "intercept",
                "support",
                "coef",
                "weights",
                "event_on",
                "event_off",
                "event_line",
                "event_censored",
            ),
            positive=("gamma", "event_scale", "event_slope"),
            positive_or_inf=("scale",),  # inf: a feature the classifier weights 0
        )
        if problems:
            raise ModelError("invalid DecisionSpec: " + "; ".join(problems))

    def __call__(self, x: ca.MX, const: _Constants = _INLINE, line: ca.MX | None = None) -> ca.MX:
        """Decision value at the row vector ``x`` (1 × d); ``line``: line pressure (bar),
        needed with ``event_line``."""
        if self.columns is not None:
            x = ca.horzcat(*(x[:, c] for c in self.columns))
        if self.kind == "event":
            return self._event(x)
        if self.kind == "local_event":
            return self._local_event(x, line)
        z = (x - const(self.mean).T) / const(self.scale).T
        if self.kind == "linear":
            return ca.dot(z.T, const(self.weights)) + self.intercept
        d = z.shape[1]
        zs, sv = ca.SX.sym("z", d), ca.SX.sym("sv", d)
        kern = ca.Function("rbf", [zs, sv], [ca.exp(-self.gamma * ca.sumsqr(zs - sv))])
        n = self.support.shape[0]
        k = kern.map(n, "serial")(z.T, const(np.ascontiguousarray(self.support.T)))
        return ca.mtimes(k, const(self.coef)) + self.intercept

    def _event_inputs(self, x: ca.MX) -> list[ca.MX]:
        """Current, dI/dt, direction, dither amplitude and frequency (0 where absent)."""
        return [x[:, c] if c >= 0 else ca.MX(0) for c in self.event_columns]

    def _event(self, x: ca.MX) -> ca.MX:
        """The latch-event law (mA): its rising / held branch where direction ≥ 0."""
        i, di, direction, a, f = self._event_inputs(x)

        def branch(c):
            c = [float(v) for v in c]
            return i - c[4] * di - (c[0] + c[1] * a + c[2] * f + c[3] * a * f)

        return ca.if_else(direction >= 0, branch(self.event_on), branch(self.event_off))

    def _local_event(self, x: ca.MX, line: ca.MX | None = None) -> ca.MX:
        """The local latch-event law (mA), as in :func:`~clutchlab.residual_ml.local_law`."""
        i, di, direction, a, f = self._event_inputs(x)
        i_raw = i
        if self.event_line is not None:
            if line is None:
                raise ModelError("this latch law follows line pressure: give the line input")
            coef, ref = (float(v) for v in np.asarray(self.event_line).ravel()[:2])
            i = i - coef * (line - ref)
        s_a, s_f = (float(v) for v in self.event_scale)
        h_slope, rho = (float(v) for v in self.event_slope)

        def moments(d2, h, i_k, r_k):
            q = d2 / h**2
            w = ca.exp(-0.5 * (q - ca.mmin(q)))
            sw = ca.sum1(w)
            mr, mi = ca.dot(w, r_k) / sw, ca.dot(w, i_k) / sw
            mrr = ca.dot(w, r_k * r_k) / sw
            return mr, mi, mrr - mr**2, ca.dot(w, r_k * i_k) / sw - mr * mi, mrr

        def branch(events):
            ev = np.asarray(events, dtype=float)
            i_k, r_k, a_k, f_k, dev_i, dev_r = (ca.DM(ev[:, j]) for j in range(6))
            d2 = (a - a_k) ** 2 / s_a**2 + (f - f_k) ** 2 / s_f**2
            q = d2 / h_slope**2
            w0 = ca.exp(-0.5 * (q - ca.mmin(q)))
            num, den = ca.dot(w0, dev_i * dev_r), ca.dot(w0, dev_r * dev_r)
            tau0 = ca.if_else(den > 1e-6 * ca.dot(w0, r_k * r_k), num / ca.fmax(den, 1e-300), 0)
            mr, mi, var_r, cov, mrr = moments(d2, float(self.gamma), i_k, r_k)
            lam = rho * mrr
            den = var_r + lam
            tau = ca.if_else(den > 0, (cov + lam * tau0) / ca.fmax(den, 1e-300), 0)
            return i - (mi - tau * mr) - tau * di

        d = ca.if_else(direction >= 0, branch(self.event_on), branch(self.event_off))
        cens = np.asarray(self.event_censored if self.event_censored is not None else [])
        if cens.size == 0:
            return d
        on = np.asarray(self.event_on, dtype=float)
        cens = cens.reshape(-1, 3)
        h = float(self.gamma)
        q_on = ((a - ca.DM(on[:, 2])) ** 2 / s_a**2 + (f - ca.DM(on[:, 3])) ** 2 / s_f**2) / h**2
        q_c = ((a - ca.DM(cens[:, 1])) ** 2 / s_a**2 + (f - ca.DM(cens[:, 2])) ** 2 / s_f**2) / h**2
        low = ca.fmin(ca.mmin(q_on), ca.mmin(q_c))
        w_on, w_c = ca.exp(-0.5 * (q_on - low)), ca.exp(-0.5 * (q_c - low))
        sw_c = ca.sum1(w_c)
        share = sw_c / (sw_c + ca.sum1(w_on))
        near = w_c >= 0.5 * ca.mmax(w_c)
        peak = ca.mmax(ca.if_else(near, ca.DM(cens[:, 0]), -1e30))
        return ca.if_else(share > 0.5, ca.fmin(d, i_raw - peak), d)


@dataclass(frozen=True)
class DidtSpec:
    """Causal dI/dt of the nominal current (least-squares slope over the last N samples)
    and the direction of travel it implies.

    The samples are ``sample_s`` apart in time (1 ms: the rate the model's features were
    computed at on 1 kHz data); the FMU resamples its input to them by its own sample
    clock, so the slope does not depend on the communication step (module docstring).

    ``N = causal_window(periods · fs / f)`` with ``fs = 1 / sample_s`` and ``f`` the dither
    frequency input: the window of :func:`clutchlab.data.causal_didt` as the feature builder
    uses it (``didt_causal_mA_s``), at most ``max_samples`` (255: 5 periods down to 19.7 Hz
    at 1 kHz). The buffer starts full of the initial current, as the offline slope assumes
    the current constant before the first sample. Direction (``direction_causal``): +1 / −1
    where the slope is above ``deadband_mA_s`` / below its negative, else held (0 at start).

    Offline the window uses the trace's median dither frequency; the FMU uses the current
    input, the same for an experiment at one dither frequency. Without dither (an input of
    0 Hz) both count in periods of :data:`~clutchlab.data.demodulate.NO_DITHER_DIDT_HZ`.
    """

    periods: float = 5.0
    max_samples: int = 255
    sample_s: float = 1e-3
    deadband_mA_s: float = 10.0

    def slope(self, buffer: ca.MX, freq: ca.MX) -> ca.MX:
        """Slope (mA/s) from ``buffer`` (newest first, mA) at dither frequency ``freq`` (Hz)."""
        m = self.max_samples
        # no dither (0 Hz): the period the offline window counts in then (a 50 Hz one)
        period = (1.0 / self.sample_s) / ca.if_else(freq > 0, freq, NO_DITHER_DIDT_HZ)
        n = ca.fmax(ca.ceil(self.periods * period - 1e-6), 4)
        n = ca.fmin(n + 1 - ca.fmod(n, 2), m)
        j = ca.DM(np.arange(m, dtype=float))
        dt = self.sample_s
        w = ca.if_else(j < n, (-j * dt + (n - 1) * dt / 2) / (dt * dt * n * (n * n - 1) / 12), 0)
        return ca.dot(w, buffer)

    def direction(self, slope: ca.MX, previous: ca.MX) -> ca.MX:
        """Direction of travel (+1 / −1, held inside the dead band) after ``previous``."""
        db = self.deadband_mA_s
        return ca.if_else(slope > db, 1.0, ca.if_else(slope < -db, -1.0, previous))


@dataclass(frozen=True)
class LagSpec:
    """The nominal current through a first-order lag (``current_lag_mA``).

    ``y ← a·y + (1 − a)·I`` per sample, ``a = exp(−1 / (tau_s · fs))``, ``fs = 1 /
    sample_s``, starting at the initial current: the exact discretization
    :func:`clutchlab.data.first_order_lag` uses offline. The FMU updates it at its sample
    instants, ``sample_s`` apart in time whatever the communication step (module docstring).
    """

    tau_s: float
    sample_s: float = 1e-3

    @property
    def pole(self) -> float:
        """``a`` (0 for no lag)."""
        if not self.tau_s > 0:
            return 0.0
        return math.exp(-1.0 / (self.tau_s * (1.0 / self.sample_s)))


def _rows(x: ca.MX, a: int, b: int) -> ca.MX:
    """Rows ``a:b`` of the column ``x`` (a 0 × 1 column when empty)."""
    return x[a:b] if b > a else ca.MX(0, 1)


def _inputs(
    physics: FmuProgram | None, latched_line: bool = False, switch_line: bool = False
) -> tuple[FmuVariable, ...]:
    if physics is not None:
        return physics.inputs
    line = (
        "line pressure: the latched plateau is line pressure less the latched GP's offset"
        if latched_line
        else "line pressure (not used by this model)"
    )
    if switch_line:
        line += "; the latch switch currents move with it"
    spec = FMU_INPUTS["command"] + (
        ("line_pressure_bar", "bar", line, LINE_PRESSURE_BAR),
        ("prime_pressure_bar", "bar", "prime pressure (not used by this model)", 0.5),
        ("oil_temp_C", "°C", "oil temperature (not used by this model)", 40.0),
    )
    # the data contract's plausible ranges, refused outside as by a physics FMU
    return tuple(FmuVariable(n, u, d, s, *input_range(n)) for n, u, d, s in spec)


def ml_program(
    gps: GPSpec | dict[int, GPSpec],
    features: tuple[str, ...],
    decision: DecisionSpec | None = None,
    didt: DidtSpec | None = None,
    physics: FmuProgram | None = None,
    with_std: bool = True,
    name: str = "clutch_gp",
    description: str = "",
    lag: LagSpec | None = None,
    latched_line: bool = False,
    step_s: float | None = None,
    stop_time_s: float | None = None,
) -> FmuProgram:
    """The FMU program of a GP model (one GP, or one per latch state with a decision).

    Parameters
    ----------
    gps : GPSpec or dict of int to GPSpec
        One GP, or ``{0: unlatched, 1: latched}`` selected by ``decision``.
    features : tuple of str
        Feature names of :data:`ML_FEATURES`, in the GPs' column order.
    decision : DecisionSpec, optional
        Latch classifier (required for two GPs); its output is ``latch_state``.
    didt : DidtSpec, optional
        Causal dI/dt and direction (required when ``didt_causal_mA_s`` or
        ``direction_causal`` is a feature).
    physics : FmuProgram, optional
        Physics program (command drive) under a residual GP: hybrid. The output
        ``clutch_pressure_bar`` is then physics + residual; the physics outputs remain.
    with_std : bool
        Output ``clutch_pressure_std_bar`` (the GPs need ``l_inv``).
    name, description : str
        Model identifier and description.
    lag : LagSpec, optional
        First-order lag of the current (required when ``current_lag_mA`` is a feature).
    latched_line : bool
        The latched GP predicts the offset below line pressure: the latched output is the
        ``line_pressure_bar`` input plus its mean (standalone models with a decision only).
    step_s : float, optional
        Communication step of the default experiment (s); default the physics program's,
        else 1 ms. What the FMU computes does not depend on it (module docstring).
    stop_time_s : float, optional
        Default experiment stop time (s); default the physics program's, else 23 s.

    Returns
    -------
    FmuProgram
    """
    gps = gps if isinstance(gps, dict) else {0: gps}
    unknown = [f for f in features if f not in ML_FEATURES]
    problems = [f"unknown feature(s) {unknown}; known: {list(ML_FEATURES)}"] if unknown else []
    if len(gps) > 1 and decision is None:
        problems.append("two GPs need a decision function")
    slopes = [f for f in features if f in _SLOPE_FEATURES]
    if slopes and didt is None:
        problems.append(f"feature(s) {', '.join(slopes)} need a DidtSpec")
    if "current_lag_mA" in features and lag is None:
        problems.append("feature current_lag_mA needs a LagSpec")
    if "physics_bar" in features and physics is None:
        problems.append("feature physics_bar needs a physics program")
    if physics is not None and physics.inputs[0].name != "current_cmd_mA":
        problems.append("a hybrid needs the command-drive physics program")
    if any(g.n_features != len(features) for g in gps.values()):
        problems.append(f"every GP must take the {len(features)} features {features}")
    if with_std and any(g.l_inv is None for g in gps.values()):
        problems.append("with_std needs l_inv in every GPSpec")
    if latched_line and (physics is not None or decision is None):
        problems.append("latched_line needs a latch decision and no physics program")
    if problems:
        raise ModelError("cannot build the ML program:\n  - " + "\n  - ".join(problems))

    inputs = _inputs(
        physics, latched_line, decision is not None and decision.event_line is not None
    )
    i_line = [u.name for u in inputs].index("line_pressure_bar")
    nv = len(inputs)
    use_didt = didt is not None and bool(slopes)
    nb = didt.max_samples if use_didt else 0
    nd = 1 if "direction_causal" in features else 0  # the held direction of travel
    nl = 1 if "current_lag_mA" in features else 0  # the lagged current
    # The sample clock of the sampled features: time since the last sample instant (s).
    clocks = {didt.sample_s} if use_didt else set()
    clocks |= {lag.sample_s} if nl else set()
    if len(clocks) > 1:
        raise ModelError(
            f"the causal dI/dt and the lag are sampled at {didt.sample_s} s and "
            f"{lag.sample_s} s: the FMU resamples its input to one rate"
        )
    ts = clocks.pop() if clocks else None
    nt = 1 if ts is not None else 0
    npx = physics.nx if physics is not None else 0
    # Internal steps of at most one sample: a step then reaches at most one sample instant.
    max_step = min(physics.max_step_s if physics is not None else 1e-3, ts or math.inf)
    pars = physics.parameters if physics is not None else ()
    if physics is None:
        pars = (
            FmuVariable(
                "max_step_s",
                "s",
                f"longest internal step; longer communication steps are split; at most "
                f"{max_step:g} s (refused above)",
                max_step,
                None,
                max_step,
            ),
        )
    npar = len(pars)
    const = _Constants()
    nx = max(npx + nb + nd + nl + nt, 1)
    x = ca.MX.sym("x", nx)
    v, dv, h, p = ca.MX.sym("v", nv), ca.MX.sym("dv", nv), ca.MX.sym("h"), ca.MX.sym("p", npar)
    xp, buf, dir0 = _rows(x, 0, npx), _rows(x, npx, npx + nb), _rows(x, npx + nb, npx + nb + nd)
    lag0 = _rows(x, npx + nb + nd, npx + nb + nd + nl)
    tau0 = _rows(x, npx + nb + nd + nl, npx + nb + nd + nl + nt)

    def features_at(
        vv: ca.MX, buffer: ca.MX, previous: ca.MX, lagged: ca.MX, phys_bar: ca.MX | None
    ):
        """Feature row (1 × d) and the direction state after it."""
        slope = didt.slope(buffer, vv[2]) if use_didt else ca.MX(0)
        direction = didt.direction(slope, previous[0]) if nd else ca.MX(0)
        cols = {
            "current_mA": vv[0],
            "current_lag_mA": lagged[0] if nl else ca.MX(0),
            "dither_amp_mA": vv[1],
            "dither_freq_Hz": vv[2],
            "didt_causal_mA_s": slope,
            "direction_causal": direction,
            "physics_bar": phys_bar if phys_bar is not None else ca.MX(0),
        }
        return ca.horzcat(*(cols[f] for f in features)), direction

    def residual(feat: ca.MX, vv: ca.MX):
        if decision is None:
            g = next(iter(gps.values()))
            mean, std = g.mean_std(feat, const, with_std)
            return mean, std, None
        latched = decision(feat, const, vv[i_line]) > 0
        g0, g1 = gps.get(0, gps.get(1)), gps.get(1, gps.get(0))
        m1, s1 = g1.mean_std(feat, const, with_std)
        if latched_line:
            m1 = m1 + vv[i_line]
        m0, s0 = g0.mean_std(feat, const, with_std)
        if with_std:
            both0, both1 = ca.vertcat(m0, s0), ca.vertcat(m1, s1)
            pair = ca.if_else(latched, both1, both0, True)
            return pair[0], pair[1], latched
        return ca.if_else(latched, m1, m0, True), None, latched

    def outputs(y_phys: ca.MX | None, vv: ca.MX, buffer: ca.MX, previous: ca.MX, lagged):
        phys_bar = y_phys[0] if y_phys is not None else None
        feat, direction = features_at(vv, buffer, previous, lagged, phys_bar)
        mean, std, latched = residual(feat, vv)
        out = [y_phys[0] + mean if y_phys is not None else mean]
        if std is not None:
            out.append(std)
        if latched is not None:
            out.append(latched)
        if y_phys is not None:
            out += [mean, y_phys[0], *(y_phys[k] for k in range(1, y_phys.shape[0]))]
        return ca.vertcat(*out), direction

    v1 = v + h * dv
    buf1, lag1, tau1 = buf, lag0, tau0
    if nt:
        # The sample clock: a step (h ≤ ts, the wrapper splits longer ones) reaches the
        # next sample instant when h ≥ ts − tau; the current there (inputs linear over the
        # step: held when the master sets no derivative) is the new sample of the slope
        # buffer and of the lag, as the feature builder computes them on samples ts apart.
        due = ts - tau0[0]
        push = h >= due - 1e-9 * ts
        v_at = v[0] + ca.fmin(ca.fmax(due, 0.0), h) * dv[0]
        tau1 = ca.if_else(push, ca.fmax(h - due, 0.0), tau0[0] + h)
        if nb:
            buf1 = ca.if_else(push, ca.vertcat(v_at, _rows(buf, 0, nb - 1)), buf)
        if nl:
            a = lag.pole
            lag1 = ca.if_else(push, a * lag0 + (1.0 - a) * v_at, lag0)
    if physics is not None:
        xp1, yp1 = physics.step(xp, v, dv, h, p)
    else:
        xp1, yp1 = xp, None
    y_step, dir1 = outputs(yp1, v1, buf1, dir0, lag1)
    x1 = ca.vertcat(xp1, buf1, dir1 if nd else dir0, lag1, tau1)
    yp0 = physics.output(xp, v, p) if physics is not None else None
    y_out, _ = outputs(yp0, v, buf, dir0, lag0)
    t_pre = ca.MX.sym("t_pre")
    pad = ca.MX.zeros(nx - npx - nb - nd - nl - nt, 1)
    rest = ca.vertcat(
        ca.repmat(v[0], nb, 1),
        ca.MX.zeros(nd, 1),
        ca.repmat(v[0], nl, 1),
        ca.MX.zeros(nt, 1),
        pad,
    )
    if x1.shape[0] < nx:
        x1 = ca.vertcat(x1, pad)
    cs = const.symbols
    step = ca.Function("step", [x, v, dv, h, p, *cs], [x1, y_step])
    output = ca.Function("output", [x, v, p, *cs], [y_out])
    if physics is not None:
        x_start = ca.vertcat(physics.start(v, dv, p, t_pre), rest)
        start = ca.Function("start", [v, dv, p, t_pre, *cs], [x_start])
        x_settle = ca.vertcat(physics.settle(xp, v, dv, h, p), _rows(x, npx, nx))
        settle = ca.Function("settle", [x, v, dv, h, p, *cs], [x_settle])
    else:
        start = ca.Function("start", [v, dv, p, t_pre, *cs], [rest])
        settle = None

    kind = "hybrid" if physics is not None else "ml"
    outs = [
        FmuVariable(
            "clutch_pressure_bar",
            "bar",
            "clutch pressure: physics + residual GP mean"
            if physics is not None
            else "clutch pressure, GP mean",
        )
    ]
    if with_std:
        outs.append(
            FmuVariable(
                "clutch_pressure_std_bar",
                "bar",
                "predictive std of the GP (latent), given its coarse std bins",
            )
        )
    if decision is not None:
        outs.append(FmuVariable("latch_state", "-", "latch classifier: 1 latched, 0 not"))
    if physics is not None:
        outs.append(FmuVariable("residual_bar", "bar", "residual GP mean added to the physics"))
        outs.append(FmuVariable("physics_pressure_bar", "bar", "physics model clutch pressure"))
        renamed = {"latch_state": "physics_latch_state"} if decision is not None else {}
        outs += [
            FmuVariable(renamed.get(o.name, o.name), o.unit, o.description)
            for o in physics.outputs[1:]
        ]
    return FmuProgram(
        name=name,
        description=description
        or (
            f"clutchlab {kind} model: {len(gps)} GP(s) on {', '.join(features)}"
            + (", latch classifier" if decision is not None else "")
        ),
        kind=kind,
        inputs=inputs,
        outputs=tuple(outs),
        parameters=pars,
        nx=nx,
        start=start,
        settle=settle,
        step=step,
        output=output,
        step_s=step_s if step_s is not None else (physics.step_s if physics else 1e-3),
        stop_time_s=stop_time_s
        if stop_time_s is not None
        else (physics.stop_time_s if physics is not None else 23.0),
        max_step_s=max_step,
        annotations={
            **(physics.annotations if physics is not None else {}),
            "kind": kind,
            "features": ",".join(features),
            "gps": str(len(gps)),
            "didt": "causal" if use_didt else "none",
        },
        constants=tuple(const.arrays),
        # a hybrid checks its physics' pressures as the physics FMU does
        pressure_outputs=tuple(
            "physics_pressure_bar" if n == "clutch_pressure_bar" else n
            for n in (physics.pressure_outputs if physics is not None else ())
        ),
        supply_inputs=physics.supply_inputs if physics is not None else (),
    )
