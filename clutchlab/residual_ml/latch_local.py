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
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import ModelError
from .latch_event import law_columns

__all__ = [
    "SLOPE_BANDWIDTH",
    "SLOPE_PRIOR",
    "LocalEventDecision",
    "fit_local_event_decision",
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


def _moments(d2: np.ndarray, h: float, i_k: np.ndarray, r_k: np.ndarray):
    """Weighted means of I and İ, variance of İ, covariance, mean square of İ."""
    q = d2 / h**2
    # Relative weights: the nearest event has weight 1, so a query far from every event
    # still gets the law of its nearest ones instead of 0/0.
    w = np.exp(-0.5 * (q - q.min(axis=1, keepdims=True)))
    sw = w.sum(axis=1)
    mr, mi = (w @ r_k) / sw, (w @ i_k) / sw
    mrr = (w @ (r_k * r_k)) / sw
    return mr, mi, mrr - mr**2, (w @ (r_k * i_k)) / sw - mr * mi, mrr


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
    i_k, r_k, a_k, f_k = events.T
    d2 = ((a_k[:, None] - a_k[None]) / scale[0]) ** 2 + ((f_k[:, None] - f_k[None]) / scale[1]) ** 2
    w = np.exp(-0.5 * d2 / h**2)
    sw = w.sum(axis=1)
    return i_k - (w @ i_k) / sw, r_k - (w @ r_k) / sw


def _prior_slope(d2, h_slope, di, dr, r_k) -> np.ndarray:
    """``τ₀``: the within-setting slope, weighted around each query (0 where undefined)."""
    q = d2 / h_slope**2
    w = np.exp(-0.5 * (q - q.min(axis=1, keepdims=True)))
    num, den = w @ (di * dr), w @ (dr * dr)
    return np.where(den > 1e-6 * (w @ (r_k * r_k)), num / np.where(den > 0, den, 1.0), 0.0)


def local_law(
    events: np.ndarray,
    scale: np.ndarray,
    h: float,
    amp: np.ndarray,
    freq: np.ndarray,
    h_slope: float = SLOPE_BANDWIDTH,
    rho: float = SLOPE_PRIOR,
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

    Returns
    -------
    theta, tau : numpy.ndarray
        Switch current at zero rate (mA) and its slope in dI/dt (s) per query.
    """
    i_k, r_k, a_k, f_k = events.T
    za = (np.asarray(amp, dtype=float)[:, None] - a_k[None]) / scale[0]
    zf = (np.asarray(freq, dtype=float)[:, None] - f_k[None]) / scale[1]
    d2 = za**2 + zf**2
    tau0 = _prior_slope(d2, h_slope, *within_setting(events, scale, h), r_k)
    mr, mi, var_r, cov, mrr = _moments(d2, h, i_k, r_k)
    lam = rho * mrr
    den = var_r + lam
    tau = np.where(den > 0, (cov + lam * tau0) / np.where(den > 0, den, 1.0), 0.0)
    return mi - tau * mr, tau


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
    """

    columns: np.ndarray
    on: np.ndarray
    off: np.ndarray
    scale: np.ndarray
    bandwidth: float
    slope_bandwidth: float = SLOPE_BANDWIDTH
    slope_prior: float = SLOPE_PRIOR

    kind = "local_event"

    def _parts(self, X: np.ndarray):
        c = [int(v) for v in self.columns]
        return [X[:, k] if k >= 0 else np.zeros(X.shape[0]) for k in c]

    def _law(self, events, amp, freq):
        return local_law(
            events, self.scale, self.bandwidth, amp, freq, self.slope_bandwidth, self.slope_prior
        )

    def __call__(self, X: np.ndarray) -> np.ndarray:
        """Decision value per row of ``X`` (mA); > 0 means latched."""
        X = np.atleast_2d(np.asarray(X, dtype=float))
        out = np.empty(X.shape[0])
        for a in range(0, X.shape[0], _CHUNK):
            i, di, direction, amp, freq = self._parts(X[a : a + _CHUNK])
            up = direction >= 0
            d = np.empty(len(i))
            for sel, ev in ((up, self.on), (~up, self.off)):
                if np.any(sel):
                    theta, tau = self._law(ev, amp[sel], freq[sel])
                    d[sel] = i[sel] - theta - tau * di[sel]
            out[a : a + _CHUNK] = d
        return out

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
        """Arrays for an NPZ file."""
        return {
            "columns": np.asarray(self.columns, dtype=float),
            "on": np.asarray(self.on, dtype=float),
            "off": np.asarray(self.off, dtype=float),
            "scale": np.asarray(self.scale, dtype=float),
            "bandwidth": np.array([self.bandwidth], dtype=float),
            "slope": np.array([self.slope_bandwidth, self.slope_prior], dtype=float),
        }

    @classmethod
    def from_arrays(cls, a: dict[str, np.ndarray]) -> LocalEventDecision:
        """Inverse of :meth:`arrays`."""
        return cls(
            np.asarray(a["columns"], dtype=float).astype(int),
            np.asarray(a["on"], dtype=float).reshape(-1, 4),
            np.asarray(a["off"], dtype=float).reshape(-1, 4),
            np.asarray(a["scale"], dtype=float),
            float(np.asarray(a["bandwidth"], dtype=float).ravel()[0]),
            *(float(v) for v in np.asarray(a["slope"], dtype=float).ravel()[:2]),
        )


def fit_local_event_decision(
    events: list[tuple[np.ndarray, int]],
    feature_names: list[str],
    bandwidth: float,
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

    by_sign = {}
    for sign, what in ((1, "latch-on"), (-1, "latch-off")):
        pick = [k for k, (_, s) in enumerate(events) if s == sign]
        if len(pick) < 2:
            raise ModelError(
                f"the local latch-event law needs at least two {what} events in the training "
                f"data, found {len(pick)}"
            )
        by_sign[sign] = table([events[k][0] for k in pick])
    both = np.vstack(list(by_sign.values()))
    scale = np.array([np.std(both[:, 2]), np.std(both[:, 3])])
    scale = np.where(scale > 1e-9 * np.maximum(np.abs(both[:, 2:]).max(axis=0), 1.0), scale, 1.0)
    return LocalEventDecision(cols, by_sign[1], by_sign[-1], scale, float(bandwidth))
