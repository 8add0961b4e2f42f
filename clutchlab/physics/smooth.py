"""Smooth replacements of the non-smooth functions of hydraulics.

Everything IPOPT sees must be twice differentiable: no ``if_else``, ``fabs``,
``fmax`` or ``sign``. These helpers work on CasADi SX/MX and on NumPy arrays.
"""

from __future__ import annotations

import casadi as ca

__all__ = [
    "logistic",
    "orifice_flow",
    "smooth_abs",
    "smooth_max0",
    "smooth_max0_slope",
    "smooth_sign",
    "smooth_window",
]


def smooth_abs(x, eps):
    """``sqrt(x² + eps²)``, a smooth ``|x|`` (same unit as ``x`` and ``eps``)."""
    return ca.sqrt(x * x + eps * eps)


def smooth_max0(x, eps):
    """Smooth ``max(x, 0)``: ``(x + sqrt(x² + eps²)) / 2`` (same unit as ``x``)."""
    return 0.5 * (x + ca.sqrt(x * x + eps * eps))


def smooth_max0_slope(x, eps):
    """Derivative of :func:`smooth_max0` in ``x``: ``(1 + x / sqrt(x² + eps²)) / 2`` (-)."""
    return 0.5 * (1.0 + x / ca.sqrt(x * x + eps * eps))


def smooth_sign(x, scale):
    """``tanh(x / scale)``, a smooth sign of ``x``."""
    return ca.tanh(x / scale)


def logistic(x):
    """Logistic sigmoid ``1 / (1 + exp(-x))`` written with ``tanh`` (overflow-free)."""
    return 0.5 * (1.0 + ca.tanh(0.5 * x))


def smooth_window(p, lo, hi, width):
    """Smooth indicator of ``lo < p < hi`` with transition ``width`` (same units as ``p``)."""
    return logistic((p - lo) / width) - logistic((p - hi) / width)


def orifice_flow(cd, area, dp, rho, p_cr):
    """Regularized orifice equation.

    ``Q = Cd·A·sqrt(2/ρ)·Δp / (Δp² + p_cr²)^¼``: turbulent (square-root law) for
    ``|Δp| ≫ p_cr``, laminar (linear) for ``|Δp| ≪ p_cr``, smooth everywhere.

    Parameters
    ----------
    cd : float or SX
        Discharge coefficient (-).
    area : float or SX
        Flow area (m²).
    dp : float or SX
        Upstream minus downstream pressure (Pa).
    rho : float or SX
        Oil density (kg/m³).
    p_cr : float or SX
        Laminar/turbulent transition pressure (Pa).

    Returns
    -------
    Volume flow (m³/s), positive from upstream to downstream.
    """
    return cd * area * ca.sqrt(2.0 / rho) * dp / (dp * dp + p_cr * p_cr) ** 0.25
