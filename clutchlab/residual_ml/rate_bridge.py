"""Interpolating between trained ramp rates: how uncertain it is.

The paper's protocol trains on two ramp rates (fast, slow) and predicts a third between them.
Whatever depends on the rate — the latch switch current, the width of the regulated
hysteresis — is then an interpolation between two rates, and two rates cannot show how it
bends between them (the default stand's latch-off current is concave in the rate). A GP's
std does not see this: along the rate its length scale is long and its std small.

The bend is modelled as a Brownian bridge in the log ramp rate ``u = ln |dI/dt|``
(mA/s) tied to the trained rates: between trained log-rates ``a < b`` the variance of the
interpolated quantity is ``Δ² · v(u)`` with ``Δ`` its change from ``a`` to ``b`` and

    v(u) = (u − a)(b − u) / (b − a)²

(0 at a trained rate, 1/4 midway); outside the trained rates it grows as the distance over
the span, ``v = dist / (b − a)``. A scale ``κ`` (calibrated on held-back training-side
rates, never on the test ramp) multiplies the std ``Δ·√v``.
"""

from __future__ import annotations

import numpy as np

__all__ = ["bridge_weight", "group_log_rates"]

#: Two rates whose logs differ by more than this belong to different ramp rates.
RATE_GAP = float(np.log(1.5))


def group_log_rates(log_rates) -> list[list[int]]:
    """Indices of ``log_rates`` grouped by ramp rate (ascending groups).

    Rates whose sorted logs lie within ``ln 1.5`` of their neighbour form one group.
    """
    x = np.asarray(log_rates, dtype=float)
    order = np.argsort(x, kind="stable")
    groups: list[list[int]] = []
    for j in order:
        if not groups or x[j] - x[groups[-1][-1]] > RATE_GAP:
            groups.append([])
        groups[-1].append(int(j))
    return groups


def bridge_weight(u, anchors) -> tuple[np.ndarray, np.ndarray]:
    """Bracketing pair and ``v(u)`` of the module docstring.

    Parameters
    ----------
    u : float or numpy.ndarray
        Log ramp rate(s), ``ln(mA/s)``.
    anchors : sequence of float
        Trained log-rates, ascending (at least two).

    Returns
    -------
    k : numpy.ndarray
        Index of the lower anchor of the pair used (``anchors[k]``, ``anchors[k + 1]``).
    v : numpy.ndarray
        ``v(u)`` (dimensionless, ≥ 0).
    """
    a = np.asarray(anchors, dtype=float)
    u = np.asarray(u, dtype=float)
    k = np.clip(np.searchsorted(a, u) - 1, 0, a.size - 2)
    lo, hi = a[k], a[k + 1]
    span = hi - lo
    v = np.where(
        u < lo, (lo - u) / span, np.where(u > hi, (u - hi) / span, (u - lo) * (hi - u) / span**2)
    )
    return k, v
