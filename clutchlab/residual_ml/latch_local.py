"""Latch decision from latch events, local in the dither setting.

The latch-event law of :mod:`~clutchlab.residual_ml.latch_event` puts every latch event of
one direction on one plane ``I = θ(A, f) + τ İ`` with ``θ`` bilinear in the dither
amplitude ``A`` and frequency ``f`` and one ``τ``. On circuits that are not ours the
switch currents of the nine dither settings do not lie on such a plane (amplitude
schedules that follow the current, friction that depends on the dither in its own way),
and the plane's misfit at a setting becomes a latch-timing error at every ramp rate. The
training protocol, however, runs every dither setting at two ramp rates, and between those
the switch current of one setting is close to linear in the rate (on the held-back 5 s and
20 s ramps of the four zoo plants, a straight line through a setting's two trained rates
misses its switch current by about 1 mA).

:class:`LocalEventDecision` fits the same law per query, by weighted least squares over the
training events of its direction, with Gaussian weights in the standardized dither
amplitude and frequency (``(A − Aₖ)/s_A``, ``(f − fₖ)/s_f``, bandwidth ``h``)::

    wₖ = exp(−½ ((A − Aₖ)² / s_A² + (f − fₖ)² / s_f²) / h²)
    (θ, τ) = argmin Σₖ wₖ (Iₖ − θ − τ İₖ)² + λ (τ − τ₀)²,   d(x) = I − θ − τ İ  (> 0: latched)

with a weak prior toward ``τ₀``, the slope of the events within a wider bandwidth
(:func:`local_law`). A small ``h`` is a setting's own line through its two rates; a large
one is one line for all settings; a setting outside the trained ones, or one trained at a
single rate, gets the law (or the slope) of its neighbours. ``h`` cannot be chosen inside
a training set with two ramp rates: leaving an experiment out asks for a setting at a
rate *without* its own event there, while the test asks for a trained setting at a new
rate. Its default is calibrated on held-back training-side ramp rates
(``studies/latch_event.py``). The decision is memoryless given the held direction of
travel, as the latch-event law's: it runs per sample in the step predictor and in the FMU.

**Line-pressure coupling.** On a circuit whose latch pilot is fed from, or balanced
against, the supply, the switch current moves with line pressure ``p`` (on the
``stribeck_supply`` zoo plant by 34–50 mA per bar of its ±0.3 bar wander, read off the data
by ``studies/switch_rate_lines.py``). The two events of a setting are then a line through
two currents that each carry a line-pressure offset, and the slope between them is wrong
at every other rate. :func:`line_coupling` tests for it inside the training set: the
leave-one-event-out residuals of the switch current and of the line pressure under the
same law (the law is linear in the values it smooths) are regressed on each other, and
the coupling ``β`` (mA/bar, one for both directions) is kept when, with ``β`` estimated
without the held-out event, it lowers the held-out RMS to at most
:data:`LINE_COUPLING_RATIO` of that without, and line pressures reassigned at random
among the events do as well in at most :data:`LINE_COUPLING_P` of the tries (with few
events a wander lines up with the law's misses by chance). The law then runs on the
corrected currents ``Iₖ − β (pₖ − p̄)``, and the decision is
``d(x) = I − β (p − p̄) − θ − τ İ``.

**Settings that never latched.** A training experiment whose current reached its peak
``I_c`` without a latch-on leaves no event, so its dither setting would borrow the law of
its latching neighbours and be predicted to latch (on ``quadratic_play`` seed 2 the 30 Hz
B setting never latches up to 1100 mA at any ramp rate). Such experiments are kept as
censored rows ``(I_c, A, f)``: where their share of the kernel weights, against the
latch-on events', exceeds one half, the decision is at most ``I − Ī_c`` (``Ī_c`` the
highest peak of the nearest of them) on either branch: not latched below the currents at
which that setting was seen not to latch. Only experiments that contradict the law are kept:
those whose peak reached the law's latch-on current at their own rise rate (a partial ramp
that stopped short of it says nothing the law does not; kept, it would release a full ramp
at its peak on the way down instead of at the latch-off current).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import ModelError
from .latch_event import law_columns

__all__ = [
    "LINE_COUPLING_P",
    "LINE_COUPLING_RATIO",
    "LINE_PERMUTATIONS",
    "SLOPE_BANDWIDTH",
    "SLOPE_PRIOR",
    "LocalEventDecision",
    "censored_share",
    "fit_local_event_decision",
    "held_out_residuals",
    "line_coupling",
    "local_law",
    "within_setting",
]
#: Rows evaluated at once (the weights are rows × events).
_CHUNK = 65536
#: Bandwidth of the neighbours' slope ``τ₀`` (standard deviations of amplitude and frequency).
SLOPE_BANDWIDTH = 1.0
#: Weight ``ρ`` of the prior ``τ ≈ τ₀`` relative to the mean square rate of the weighted
#: events: about 2 % of a setting's own slope when it has its two trained rates.
SLOPE_PRIOR = 0.01
#: The line-pressure coupling is kept when it lowers the held-out RMS of the switch
#: currents to at most this fraction of that without it (nested leave-one-event-out).
#: Set from a prototype's ratios on held-back training-side ramps (no medium ramp in
#: them): 0.26–0.45 on the supply-coupled plant, 0.93–1.03 on the stand and the three other
#: zoo plants, seeds 0–2; measured again on this code by ``studies/latch_event.py --line``.
LINE_COUPLING_RATIO = 0.8
#: ... and when line pressures reassigned at random among the events do as well in at most
#: this share of :data:`LINE_PERMUTATIONS` tries (a one-sided permutation test).
LINE_COUPLING_P = 0.05
LINE_PERMUTATIONS = 199


def _moments(d2: np.ndarray, h: float, i_k: np.ndarray, r_k: np.ndarray):
    """Weighted means of I and İ, variance of İ, covariance, mean square of İ.

    ``i_k`` is ``(n, m)`` (``m`` value columns); the means of I and the covariances are
    ``(queries, m)``, the rest ``(queries, 1)``.
    """
    q = d2 / h**2
    # Relative weights: the nearest event has weight 1, so a query far from every event
    # still gets the law of its nearest ones instead of 0/0.
    w = np.exp(-0.5 * (q - q.min(axis=1, keepdims=True)))
    sw = w.sum(axis=1, keepdims=True)
    mr, mi = (w @ r_k)[:, None] / sw, (w @ i_k) / sw
    mrr = (w @ (r_k * r_k))[:, None] / sw
    return mr, mi, mrr - mr**2, (w @ (r_k[:, None] * i_k)) / sw - mr * mi, mrr


def within_setting(events: np.ndarray, scale: np.ndarray, h: float) -> tuple[np.ndarray, ...]:
    """Each event's current and rate less their weighted means at its own setting.

    The means use the law's weights (bandwidth ``h``) around the event, so an event whose
    setting was trained at one rate only has deviations near 0 and tells nothing about the
    slope, while the two events of a setting trained at two rates give its own slope.

    Returns
    -------
    di, dr : numpy.ndarray
        Deviations of the switch current (mA) and of the rate (mA/s).
    """
    return _within_setting(events, events[:, 0], scale, h)


def _within_setting(events, values, scale, h):
    """:func:`within_setting` with ``values`` (``(n,)`` or ``(n, m)``) in place of I."""
    _, r_k, a_k, f_k = events.T
    d2 = ((a_k[:, None] - a_k[None]) / scale[0]) ** 2 + ((f_k[:, None] - f_k[None]) / scale[1]) ** 2
    w = np.exp(-0.5 * d2 / h**2)
    sw = w.sum(axis=1)
    mean_v = (w @ values) / (sw[:, None] if values.ndim == 2 else sw)
    return values - mean_v, r_k - (w @ r_k) / sw


def _prior_slope(d2, h_slope, di, dr, r_k) -> np.ndarray:
    """``τ₀``: the within-setting slope, weighted around each query (0 where undefined).

    ``di`` is ``(n, m)``; the slopes are ``(queries, m)``.
    """
    q = d2 / h_slope**2
    w = np.exp(-0.5 * (q - q.min(axis=1, keepdims=True)))
    num, den = w @ (di * dr[:, None]), (w @ (dr * dr))[:, None]
    ok = den > 1e-6 * (w @ (r_k * r_k))[:, None]
    return np.where(ok, num / np.where(den > 0, den, 1.0), 0.0)


def local_law(
    events: np.ndarray,
    scale: np.ndarray,
    h: float,
    amp: np.ndarray,
    freq: np.ndarray,
    h_slope: float = SLOPE_BANDWIDTH,
    rho: float = SLOPE_PRIOR,
    values: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """``θ`` (mA) and ``τ`` (s) of the weighted event law at each ``(amp, freq)``.

    ``(θ, τ)`` minimize ``Σ wₖ (Iₖ − θ − τ İₖ)² + λ (τ − τ₀)²``: weights of bandwidth
    ``h``, and a weak prior toward ``τ₀``, the within-setting slope of the events
    (:func:`within_setting`) weighted with the wider ``h_slope`` (``λ = ρ Σ wₖ İₖ² / Σ wₖ``,
    ``ρ`` default :data:`SLOPE_PRIOR`). A setting with events at two rates keeps its own
    slope; one with a single rate (a rate left out, or a protocol with one) borrows its
    neighbours'.

    Parameters
    ----------
    events : numpy.ndarray
        ``(n, 4)``: switch current (mA), dI/dt (mA/s), dither amplitude (mA) and
        frequency (Hz) of each training event of one direction.
    scale : numpy.ndarray
        Standard deviations of amplitude (mA) and frequency (Hz) the distances use.
    h, h_slope : float
        Bandwidths of the law and of the neighbours' slope (in those standard deviations).
    rho : float
        Weight of the slope prior (dimensionless).
    amp, freq : numpy.ndarray
        Query dither amplitude (mA) and frequency (Hz).
    values : numpy.ndarray, optional
        ``(n,)`` or ``(n, m)``: values smoothed in place of the switch currents (units of
        the values; default the currents). The law is linear in them, so ``m`` columns
        cost one evaluation.

    Returns
    -------
    theta, tau : numpy.ndarray
        Switch current at zero rate (mA) and its slope in dI/dt (s) per query; with
        ``(n, m)`` values, ``(queries, m)`` (value units, and value units per mA/s).
    """
    _, r_k, a_k, f_k = events.T
    v = events[:, 0] if values is None else np.asarray(values, dtype=float)
    v2 = v.reshape(len(r_k), -1)
    za = (np.asarray(amp, dtype=float)[:, None] - a_k[None]) / scale[0]
    zf = (np.asarray(freq, dtype=float)[:, None] - f_k[None]) / scale[1]
    d2 = za**2 + zf**2
    tau0 = _prior_slope(d2, h_slope, *_within_setting(events, v2, scale, h), r_k)
    mr, mi, var_r, cov, mrr = _moments(d2, h, v2, r_k)
    lam = rho * mrr
    den = var_r + lam
    tau = np.where(den > 0, (cov + lam * tau0) / np.where(den > 0, den, 1.0), 0.0)
    theta = mi - tau * mr
    if v.ndim == 1:
        return theta[:, 0], tau[:, 0]
    return theta, tau


def held_out_residuals(
    events: np.ndarray, scale: np.ndarray, h: float, values: np.ndarray
) -> np.ndarray:
    """Leave-one-event-out residual of ``values`` under the law of ``events``.

    Each event's ``value`` is predicted by :func:`local_law` fitted to the other events
    with their ``values`` in place of the switch current (``θ + τ İₖ``). The law is
    linear in the values it smooths, so the residuals of the currents and of any signal
    at the events (the line pressure) are those of one and the same predictor.

    Parameters
    ----------
    events : numpy.ndarray
        ``(n, 4)`` events of one direction (current mA, dI/dt mA/s, amplitude mA,
        frequency Hz).
    scale : numpy.ndarray
        Amplitude (mA) and frequency (Hz) scales of the distances.
    h : float
        Bandwidth of the law.
    values : numpy.ndarray
        ``(n,)`` value per event, or ``(n, m)``: ``m`` values per event, each column held
        out on its own (units of the values).

    Returns
    -------
    numpy.ndarray
        Held-out residuals (value − prediction), the shape and units of ``values``.
    """
    ev = np.asarray(events, dtype=float)
    vals = np.asarray(values, dtype=float)
    out = np.empty_like(vals)
    for k in range(len(ev)):
        rest = np.delete(ev, k, axis=0)
        theta, tau = local_law(
            rest, scale, h, ev[k : k + 1, 2], ev[k : k + 1, 3], values=np.delete(vals, k, axis=0)
        )
        out[k] = vals[k] - (theta[0] + tau[0] * ev[k, 1])
    return out


def _held_out_operator(events: np.ndarray, scale: np.ndarray, h: float) -> np.ndarray:
    """``H`` with :func:`held_out_residuals` ``= H @ values`` (the law is linear in them).

    Column ``j`` is the residuals of the ``j``-th unit vector: one law evaluation per
    held-out event for all ``n`` columns.
    """
    return held_out_residuals(events, scale, h, np.eye(len(events)))


def _nested_ratio(e: np.ndarray, g: np.ndarray) -> float:
    """Held-out RMS of ``e − β₋ₖ gₖ`` over that of ``e``, ``β₋ₖ`` fitted without ``k``."""
    gg, eg = float(g @ g), float(e @ g)
    nested = e - (eg - e * g) / np.maximum(gg - g * g, 1e-300) * g
    return float(np.sqrt(np.mean(nested**2) / np.mean(e**2)))


def line_coupling(
    sides: list[tuple[np.ndarray, np.ndarray]],
    scale: np.ndarray,
    h: float,
    permutations: int | None = None,
) -> tuple[float, float, float, float]:
    """The switch currents' coupling to line pressure, tested by leave-one-event-out.

    Parameters
    ----------
    sides : list of (numpy.ndarray, numpy.ndarray)
        Per direction: its ``(n, 4)`` events and the line pressure at each (bar).
    scale : numpy.ndarray
        Amplitude (mA) and frequency (Hz) scales of the distances.
    h : float
        Bandwidth of the law.
    permutations : int, optional
        Random reassignments of the line pressures to the events for the p-value
        (default :data:`LINE_PERMUTATIONS`).

    Returns
    -------
    coef : float
        ``β`` (mA/bar): the held-out current residuals regressed on the held-out line
        pressure residuals, pooled over both directions.
    reference : float
        ``p̄`` (bar), the mean line pressure at the events.
    ratio : float
        Held-out RMS with ``β`` (estimated without each held-out event) over that without
        (dimensionless; NaN when the line pressure or the held-out error is nil).
    p_value : float
        Share of reassignments of the line pressures among the events (seeded, so
        repeatable) whose ratio is at most ``ratio``: the chance that line pressure
        unrelated to the switches does as well. With few events a wander can line up
        with the law's held-out misses by chance (two settings at two rates: a ratio of
        0.45 on the default stand, whose latch does not see line pressure).
    """
    reference = float(np.mean(np.concatenate([p for _, p in sides])))
    ops = [_held_out_operator(ev, scale, h) for ev, _ in sides]
    e = np.concatenate([H @ ev[:, 0] for H, (ev, _) in zip(ops, sides, strict=True)])
    p = np.concatenate([pk for _, pk in sides]) - reference
    cuts = np.cumsum([len(pk) for _, pk in sides])[:-1]

    def g_of(values: np.ndarray) -> np.ndarray:
        parts = np.split(values, cuts)
        return np.concatenate([H @ v for H, v in zip(ops, parts, strict=True)])

    g = g_of(p)
    if not (g @ g > 1e-12 * len(g) and e @ e > 0):
        return 0.0, reference, float("nan"), float("nan")
    ratio = _nested_ratio(e, g)
    rng = np.random.default_rng(0)
    permutations = LINE_PERMUTATIONS if permutations is None else int(permutations)
    hits = sum(_nested_ratio(e, g_of(rng.permutation(p))) <= ratio for _ in range(permutations))
    return float(e @ g) / float(g @ g), reference, ratio, (1 + hits) / (1 + permutations)


@dataclass(frozen=True)
class LocalEventDecision:
    """``d(x)`` of the module docstring; > 0 means latched.

    Attributes
    ----------
    columns : numpy.ndarray
        Indices (int) of current, dI/dt, direction, dither amplitude and dither frequency
        in the decision's input rows (−1: not an input, taken as 0).
    on, off : numpy.ndarray
        ``(n, 4)`` latch-on / latch-off events: current (mA), dI/dt (mA/s), dither
        amplitude (mA), dither frequency (Hz).
    scale : numpy.ndarray
        Standard deviations of the events' amplitude (mA) and frequency (Hz); 1 where
        they do not vary.
    bandwidth : float
        ``h`` of the weights, in those standard deviations.
    slope_bandwidth, slope_prior : float
        ``h_slope`` and ``ρ`` of :func:`local_law`.
    line_coef : float
        ``β`` (mA/bar) of the line-pressure coupling; 0 when not kept (the events are then
        the measured ones, otherwise corrected to ``p̄``).
    line_reference : float
        ``p̄`` (bar).
    line_ratio, line_p_value : float
        Held-out RMS ratio and permutation p-value of :func:`line_coupling` (NaN: not
        tested, e.g. no line pressure logged).
    censored : numpy.ndarray
        ``(m, 3)``: peak current (mA), dither amplitude (mA) and frequency (Hz) of the
        training experiments that never latched (empty: none).
    """

    columns: np.ndarray
    on: np.ndarray
    off: np.ndarray
    scale: np.ndarray
    bandwidth: float
    slope_bandwidth: float = SLOPE_BANDWIDTH
    slope_prior: float = SLOPE_PRIOR
    line_coef: float = 0.0
    line_reference: float = 0.0
    line_ratio: float = float("nan")
    line_p_value: float = float("nan")
    censored: np.ndarray = field(default_factory=lambda: np.empty((0, 3)))

    kind = "local_event"

    def _parts(self, X: np.ndarray):
        c = [int(v) for v in self.columns]
        return [X[:, k] if k >= 0 else np.zeros(X.shape[0]) for k in c]

    def _law(self, events, amp, freq):
        return local_law(
            events, self.scale, self.bandwidth, amp, freq, self.slope_bandwidth, self.slope_prior
        )

    @property
    def uses_line(self) -> bool:
        """Whether the decision needs the line pressure (a kept coupling)."""
        return self.line_coef != 0.0

    def line_shift(self, line_bar) -> np.ndarray:
        """``β (p − p̄)`` (mA) at line pressure ``line_bar`` (bar)."""
        return self.line_coef * (np.asarray(line_bar, dtype=float) - self.line_reference)

    def __call__(self, X: np.ndarray, line: np.ndarray | None = None) -> np.ndarray:
        """Decision value per row of ``X`` (mA); > 0 means latched.

        ``line`` (bar, per row) is required when :attr:`uses_line`.
        """
        X = np.atleast_2d(np.asarray(X, dtype=float))
        if self.uses_line and line is None:
            raise ModelError(
                "this latch decision follows line pressure (a coupling of "
                f"{self.line_coef:+.1f} mA/bar was kept in training): give the line pressure"
            )
        out = np.empty(X.shape[0])
        for a in range(0, X.shape[0], _CHUNK):
            i, di, direction, amp, freq = self._parts(X[a : a + _CHUNK])
            up = direction >= 0
            d = np.empty(len(i))
            for sel, ev in ((up, self.on), (~up, self.off)):
                if np.any(sel):
                    theta, tau = self._law(ev, amp[sel], freq[sel])
                    d[sel] = i[sel] - theta - tau * di[sel]
            if self.uses_line:
                d -= self.line_shift(np.asarray(line, dtype=float)[a : a + _CHUNK])
            out[a : a + _CHUNK] = self._censor(d, i, amp, freq)
        return out

    def _censor(self, d: np.ndarray, i: np.ndarray, amp: np.ndarray, freq: np.ndarray):
        """``d``, at most ``I − Ī_c`` where censored rows hold most of the weight."""
        if len(self.censored) == 0:
            return d
        share, peak = censored_share(self.on, self.censored, self.scale, self.bandwidth, amp, freq)
        return np.where(share > 0.5, np.minimum(d, i - peak), d)

    def events_with_deviations(self, events: np.ndarray) -> np.ndarray:
        """``(n, 6)``: the events and their :func:`within_setting` deviations (mA, mA/s)."""
        ev = np.asarray(events, dtype=float)
        return np.column_stack([ev, *within_setting(ev, self.scale, self.bandwidth)])

    def thresholds(self, amp_mA: float, freq_Hz: float) -> tuple[float, float]:
        """Latch-on and latch-off current (mA) at zero rate for one dither setting."""
        a, f = np.array([amp_mA], dtype=float), np.array([freq_Hz], dtype=float)
        on, off = self._law(self.on, a, f)[0], self._law(self.off, a, f)[0]
        return float(on[0]), float(off[0])

    def arrays(self) -> dict[str, np.ndarray]:
        """Arrays for an NPZ file (``censored`` only when there are such rows)."""
        extra = {"censored": np.asarray(self.censored, dtype=float)} if len(self.censored) else {}
        return extra | {
            "columns": np.asarray(self.columns, dtype=float),
            "on": np.asarray(self.on, dtype=float),
            "off": np.asarray(self.off, dtype=float),
            "scale": np.asarray(self.scale, dtype=float),
            "bandwidth": np.array([self.bandwidth], dtype=float),
            "slope": np.array([self.slope_bandwidth, self.slope_prior], dtype=float),
            # −1: not tested (the file holds finite numbers only)
            "line": np.array(
                [
                    self.line_coef,
                    self.line_reference,
                    np.nan_to_num(self.line_ratio, nan=-1.0),
                    np.nan_to_num(self.line_p_value, nan=-1.0),
                ]
            ),
        }

    @classmethod
    def from_arrays(cls, a: dict[str, np.ndarray]) -> LocalEventDecision:
        """Inverse of :meth:`arrays` (files written before the coupling: none)."""
        line = np.asarray(a.get("line", [0.0, 0.0, -1.0, -1.0]), dtype=float).ravel()
        ratio, p_value = (float(v) if v >= 0 else float("nan") for v in line[2:4])
        return cls(
            np.asarray(a["columns"], dtype=float).astype(int),
            np.asarray(a["on"], dtype=float).reshape(-1, 4),
            np.asarray(a["off"], dtype=float).reshape(-1, 4),
            np.asarray(a["scale"], dtype=float),
            float(np.asarray(a["bandwidth"], dtype=float).ravel()[0]),
            *(float(v) for v in np.asarray(a["slope"], dtype=float).ravel()[:2]),
            float(line[0]),
            float(line[1]),
            ratio,
            p_value,
            np.asarray(a.get("censored", np.empty((0, 3))), dtype=float).reshape(-1, 3),
        )


def censored_share(
    on: np.ndarray,
    censored: np.ndarray,
    scale: np.ndarray,
    h: float,
    amp: np.ndarray,
    freq: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Share of the censored rows in the kernel weights and their weighted peak current.

    Parameters
    ----------
    on : numpy.ndarray
        ``(n, 4)`` latch-on events (current mA, dI/dt mA/s, amplitude mA, frequency Hz).
    censored : numpy.ndarray
        ``(m, 3)`` never-latched experiments: peak current (mA), amplitude (mA),
        frequency (Hz); ``m ≥ 1``.
    scale : numpy.ndarray
        Amplitude (mA) and frequency (Hz) scales of the distances.
    h : float
        Bandwidth of the law.
    amp, freq : numpy.ndarray
        Query dither amplitude (mA) and frequency (Hz).

    Returns
    -------
    share : numpy.ndarray
        Censored weight over censored plus latch-on weight (dimensionless) per query.
    peak : numpy.ndarray
        Highest peak current (mA) of the censored rows with at least half the largest
        censored weight, per query (the setting's own experiments at every ramp rate).
    """
    amp = np.asarray(amp, dtype=float)[:, None]
    freq = np.asarray(freq, dtype=float)[:, None]

    def q(a_k, f_k):
        return (((amp - a_k[None]) / scale[0]) ** 2 + ((freq - f_k[None]) / scale[1]) ** 2) / h**2

    q_on, q_c = q(on[:, 2], on[:, 3]), q(censored[:, 1], censored[:, 2])
    low = np.minimum(q_on.min(axis=1), q_c.min(axis=1))[:, None]
    w_on, w_c = np.exp(-0.5 * (q_on - low)), np.exp(-0.5 * (q_c - low))
    sw_c = w_c.sum(axis=1)
    near = w_c >= 0.5 * w_c.max(axis=1, keepdims=True)
    peak = np.where(near, censored[None, :, 0], -np.inf).max(axis=1)
    return sw_c / (sw_c + w_on.sum(axis=1)), peak


def fit_local_event_decision(
    events: list[tuple[np.ndarray, int]],
    feature_names: list[str],
    bandwidth: float,
    line: np.ndarray | None = None,
    censored: list[np.ndarray] | None = None,
) -> LocalEventDecision:
    """Collect the local latch-event law's training events.

    Parameters
    ----------
    events : list of (numpy.ndarray, int)
        One feature row (``feature_names`` order) per latch event and its direction: +1
        latch-on, −1 latch-off (:func:`~clutchlab.residual_ml.latch_event.latch_events`).
    feature_names : list of str
        Names of the row's columns; they must include a current feature, a dI/dt feature
        and a direction feature.
    bandwidth : float
        ``h`` (> 0), in standard deviations of the events' amplitude and frequency.
    line : numpy.ndarray, optional
        Line pressure (bar) at each event: the coupling is tested (:func:`line_coupling`)
        and kept when its held-out ratio is at most :data:`LINE_COUPLING_RATIO` and its
        permutation p-value at most :data:`LINE_COUPLING_P`.
    censored : list of numpy.ndarray, optional
        One feature row (``feature_names`` order) per training experiment that never
        latched, at its peak current, with the rise's dI/dt (mA/s) in its dI/dt column.
        Kept (as ``censored``) only where the peak reached the law's latch-on current
        at that rate.

    Returns
    -------
    LocalEventDecision

    Raises
    ------
    ModelError
        If a needed feature is missing, there are fewer than two events of each kind, or
        the bandwidth is not a positive number.
    """
    names = list(feature_names)
    cols = law_columns(names, "local latch-event law")
    if not (np.isfinite(bandwidth) and bandwidth > 0):
        raise ModelError(f"the latch bandwidth must be a positive number, got {bandwidth!r}")

    def table(rows: list[np.ndarray]) -> np.ndarray:
        x = np.asarray(rows, dtype=float).reshape(len(rows), -1)
        picked = cols[[0, 1, 3, 4]]
        return np.column_stack([x[:, c] if c >= 0 else np.zeros(len(x)) for c in picked])

    by_sign, picks = {}, {}
    for sign, what in ((1, "latch-on"), (-1, "latch-off")):
        pick = [k for k, (_, s) in enumerate(events) if s == sign]
        if len(pick) < 2:
            raise ModelError(
                f"the local latch-event law needs at least two {what} events in the training "
                f"data, found {len(pick)}"
            )
        by_sign[sign], picks[sign] = table([events[k][0] for k in pick]), pick
    both = np.vstack(list(by_sign.values()))
    scale = np.array([np.std(both[:, 2]), np.std(both[:, 3])])
    scale = np.where(scale > 1e-9 * np.maximum(np.abs(both[:, 2:]).max(axis=0), 1.0), scale, 1.0)
    cens = np.empty((0, 3))
    if censored:
        rows = table(list(censored))  # current at the peak, rise rate, amplitude, frequency
        theta, tau = local_law(by_sign[1], scale, float(bandwidth), rows[:, 2], rows[:, 3])
        # only experiments that reached the law's latch-on current (at their own rise rate)
        # without latching contradict it; one that stopped short tells nothing new
        cens = rows[rows[:, 0] >= theta + tau * rows[:, 1]][:, [0, 2, 3]]
    if line is None:
        return LocalEventDecision(
            cols, by_sign[1], by_sign[-1], scale, float(bandwidth), censored=cens
        )
    p = np.asarray(line, dtype=float)
    if p.shape != (len(events),) or not np.all(np.isfinite(p)):
        raise ModelError(
            f"the line pressure at the latch events must be {len(events)} finite values"
        )
    sides = [(by_sign[s], p[picks[s]]) for s in (1, -1)]
    coef, ref, ratio, p_value = line_coupling(sides, scale, float(bandwidth))
    # NaN (no variation, nothing to explain) is not kept either.
    if not (ratio <= LINE_COUPLING_RATIO and p_value <= LINE_COUPLING_P):
        return LocalEventDecision(
            cols,
            by_sign[1],
            by_sign[-1],
            scale,
            float(bandwidth),
            line_ratio=ratio,
            line_p_value=p_value,
            censored=cens,
        )
    on, off = (ev - np.outer(coef * (pk - ref), [1.0, 0.0, 0.0, 0.0]) for ev, pk in sides)
    return LocalEventDecision(
        cols,
        on,
        off,
        scale,
        float(bandwidth),
        line_coef=coef,
        line_reference=ref,
        line_ratio=ratio,
        line_p_value=p_value,
        censored=cens,
    )
