"""A signal's association with the residual in the regulated region, beyond each experiment's
own piecewise-linear map of the current and its direction.

Issue 17, "signatures that see through a poor base fit". On a circuit whose equations are
not clutchlab's, the fitted model leaves a residual of a few tenths of a bar that repeats
with the ramp (a misplaced band, a misplaced latch window), and a missing effect that follows
another signal — the regulated pressure moving with line-pressure wander — is a few
hundredths of a bar under it. The pooled map of :func:`~.diagnostics.current_map_residual`
cannot remove a misfit that differs from one ramp rate to the next, and the latch windows'
residual, which no map of the current removes, drowns what is left. So here:

* only the **regulated** samples count (the measured *and* the predicted pressure more than
  :data:`REGULATED_MARGIN_BAR` below line pressure): on the latched plateau the pressure is
  line pressure itself, and the latch windows — where one of the two has latched and the
  other not — are what the map cannot hold;
* the map is fitted **per experiment**: in each cell of (experiment × direction of travel ×
  :data:`PARTIAL_CURRENT_BINS` quantile bins of the current) the residual and the signal are
  both freed of their mean and of their linear trend in the current (Frisch–Waugh), so a
  misfit that repeats with the ramp, and a signal that moves monotonically with it (an oil
  that warms through every run), are removed with the map;
* what is left is compared by the partial correlation ``ρ``, with an effective sample size
  that allows for the autocorrelation of both series (``Σ_e n_e / max(τ_r, τ_x)``, per
  experiment), and its ``z = ρ √n_eff``. The integrated times are taken on each
  experiment's regulated samples joined end to end, across the gap of the latched plateau:
  an approximation.

A signal that the current determines — the same function of the current, per direction, in
every experiment (a dither faded in with the current below some level) — gets no statistic:
a kinked function of the current is not removed by a cell's linear trend, and what is left of
it cannot be told from a misfit in the current. It is recognized when a piecewise-linear map
of the current per direction, pooled over the experiments (:data:`CURRENT_MAP_KNOTS` quantile
knots), explains at least :data:`CURRENT_DETERMINED_R2` of its variance over the regulated
samples. On the zoo's datasets (session 29; four plants, line-coupling, null and oil-drift
cases, 20 discoveries' base fits) the dither amplitude gives 0.998–0.999, line pressure
0.21–0.25, and an oil that warms through every run 0.885–0.887. That oil is kept, and its
trend goes with each experiment's map as above.

A signal enters a residual's signature on this evidence when ``|z| ≥`` :data:`PARTIAL_Z` and
``ρ² ≥`` :data:`PARTIAL_R2`. Measured on quadratic_play seed 0 (three dither settings, fast +
slow training ramps, its own ``clutchlab fit-physics``): with the zoo's line-pressure coupling
(0.43 bar/bar) ``ρ`` = −0.20 … −0.26 for 4–16 bins (β −0.28 … −0.30 bar/bar); the same plant
without it −0.01 … +0.01. The predicted pressure joined the region's definition after a
discovery's base fit on that coupled dataset latched early at 81 of 23 735 samples, which
alone pulled ``z`` from −9.6 to −4.0 (BENCHMARKS, issue 17, session 28).
"""

from __future__ import annotations

import math

import numpy as np

from .residuals import ResidualSet, integrated_time

__all__ = [
    "CURRENT_DETERMINED_R2",
    "CURRENT_MAP_KNOTS",
    "MIN_REGULATED",
    "PARTIAL_CURRENT_BINS",
    "PARTIAL_R2",
    "PARTIAL_Z",
    "REGULATED_MARGIN_BAR",
    "current_determined_share",
    "partial_hit",
    "quantile_bins",
    "regulated_mask",
    "regulated_partial",
]

#: A sample is regulated when the measured pressure is more than this below line pressure (bar).
REGULATED_MARGIN_BAR = 1.0
#: Quantile bins of the current per experiment and direction of travel.
PARTIAL_CURRENT_BINS = 8
#: |z| a partial correlation needs to enter the signature.
PARTIAL_Z = 4.0
#: ρ² a partial correlation needs to enter the signature (its share of what the map leaves).
PARTIAL_R2 = 0.02
#: Knots (quantiles of the current, per direction) of the map that tests whether the current
#: determines a signal.
CURRENT_MAP_KNOTS = 32
#: Share of a signal's variance that map must explain for the signal to count as a function
#: of the current (and get no statistic).
CURRENT_DETERMINED_R2 = 0.99
#: Fewest regulated samples for the statistic.
MIN_REGULATED = 50


def _cells(exp: np.ndarray, direction: np.ndarray, current: np.ndarray) -> np.ndarray:
    """Cell index of every sample: experiment × direction × current quantile bin."""
    cell = np.zeros(current.size, dtype=int)
    next_id = 0
    for e in np.unique(exp):
        for d in np.unique(direction[exp == e]):
            sel = (exp == e) & (direction == d)
            k, n_bins = quantile_bins(current[sel], PARTIAL_CURRENT_BINS)
            cell[sel] = next_id + k
            next_id += n_bins
    return cell


def quantile_bins(x: np.ndarray, n: int) -> tuple[np.ndarray, int]:
    """Label of every value of ``x`` among at most ``n`` quantile bins, and the bin count
    (fewer where quantiles coincide; at least 1)."""
    edges = np.unique(np.quantile(x, np.linspace(0, 1, n + 1)))
    labels = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, max(len(edges) - 2, 0))
    return labels, max(len(edges) - 1, 1)


def _negligible(sum_sq: float, x: np.ndarray) -> bool:
    """Whether a sum of squared deviations of ``x`` is negligible against ``x``'s own size
    (the signal does not move)."""
    return sum_sq <= 1e-12 * max(float(np.sum(x * x)), 1e-300)


def current_determined_share(x: np.ndarray, current: np.ndarray, direction: np.ndarray) -> float:
    """Share of the variance of ``x`` that a piecewise-linear map of ``current`` per
    ``direction`` explains (pooled over the experiments): the mean of ``x`` in each of
    :data:`CURRENT_MAP_KNOTS` quantile bins, at the bin's median current, interpolated.
    1 for a constant ``x`` (nothing left to explain)."""
    total = float(np.sum((x - x.mean()) ** 2))
    if _negligible(total, x):
        return 1.0
    left = 0.0
    for d in np.unique(direction):
        sel = direction == d
        xs, cs = x[sel], current[sel]
        k, n_bins = quantile_bins(cs, CURRENT_MAP_KNOTS)
        counts = np.maximum(np.bincount(k, minlength=n_bins), 1)
        means = np.bincount(k, weights=xs, minlength=n_bins) / counts
        knots = np.array(
            [np.median(cs[k == j]) if np.any(k == j) else np.nan for j in range(n_bins)]
        )
        ok = np.isfinite(knots)
        order = np.argsort(knots[ok])
        fit = np.interp(cs, knots[ok][order], means[ok][order])
        left += float(np.sum((xs - fit) ** 2))
    return 1.0 - left / total


def _detrend(v: np.ndarray, cell: np.ndarray, current: np.ndarray) -> np.ndarray:
    """``v`` minus its mean and its linear trend in the current within each cell."""
    n = np.maximum(np.bincount(cell), 1)
    c_mean = (np.bincount(cell, weights=current) / n)[cell]
    v_mean = (np.bincount(cell, weights=v) / n)[cell]
    dc, dv = current - c_mean, v - v_mean
    s_cc = np.bincount(cell, weights=dc * dc)
    s_cv = np.bincount(cell, weights=dc * dv)
    slope = np.divide(s_cv, s_cc, out=np.zeros_like(s_cv), where=s_cc > 1e-12)
    return dv - slope[cell] * dc


def regulated_mask(res: ResidualSet) -> np.ndarray:
    """Which kept residuals lie in the regulated region: the measured and the predicted
    pressure (``pressure_bar`` plus the residual) both more than
    :data:`REGULATED_MARGIN_BAR` below line pressure. Boolean, one per kept residual."""
    keep = res.keep
    pressure = res.signals["pressure_bar"][keep]
    below = res.signals["line_pressure_bar"][keep] - REGULATED_MARGIN_BAR
    return (pressure < below) & (pressure + res.r[keep] < below)


def regulated_partial(res: ResidualSet, signal: str) -> dict | None:
    """Partial association of ``signal`` with the kept residual in the regulated region.

    Parameters
    ----------
    res : ResidualSet
        Residuals (bar, model minus measured) and signals; ``pressure_bar`` (measured),
        ``pressure_bar`` plus the residual (predicted) and ``line_pressure_bar`` decide the
        regulated samples.
    signal : str
        A signal of the residual set (its own unit).

    Returns
    -------
    dict or None
        ``rho`` (partial correlation), ``z``, ``n_eff``, ``beta`` (bar per unit of the
        signal), ``effect_bar`` (RMS of ``beta`` times what the map leaves of the signal,
        bar) and ``n`` (regulated samples); None when there are too few regulated samples,
        the current determines the signal, or it does not move within the map's cells.
    """
    keep = res.keep
    r = res.r[keep]
    x = np.asarray(res.signals[signal][keep], dtype=float)
    regulated = regulated_mask(res)
    if int(regulated.sum()) < MIN_REGULATED:
        return None
    exp = np.zeros(r.size, dtype=int)
    for k, (a, b) in enumerate(res.kept_slices):
        exp[a:b] = k
    exp, r, x = exp[regulated], r[regulated], x[regulated]
    current = res.signals["current_mA"][keep][regulated]
    direction = np.sign(res.signals["didt_sign"][keep][regulated]).astype(int)
    if current_determined_share(x, current, direction) >= CURRENT_DETERMINED_R2:
        return None
    cell = _cells(exp, direction, current)
    rr, xx = _detrend(r, cell, current), _detrend(x, cell, current)
    s_rr, s_xx, s_rx = float(rr @ rr), float(xx @ xx), float(rr @ xx)
    if s_rr <= 0 or _negligible(s_xx, x):
        return None
    n_eff = 0.0
    for e in np.unique(exp):
        sel = exp == e
        tau = max(integrated_time(rr[sel]), integrated_time(xx[sel]))
        n_eff += max(int(sel.sum()) / tau, 1.0)
    rho = s_rx / math.sqrt(s_rr * s_xx)
    beta = s_rx / s_xx
    return {
        "rho": float(rho),
        "z": float(rho * math.sqrt(n_eff)),
        "n_eff": float(n_eff),
        "beta": float(beta),
        "effect_bar": float(abs(beta) * math.sqrt(s_xx / xx.size)),
        "n": int(xx.size),
    }


def partial_hit(partial: dict | None) -> bool:
    """Whether a :func:`regulated_partial` result puts its signal in the signature."""
    if not partial:
        return False
    return abs(partial["z"]) >= PARTIAL_Z and partial["rho"] ** 2 >= PARTIAL_R2
