"""Reference integration with SciPy's adaptive Radau IIA (accuracy checks only)."""

from __future__ import annotations

import casadi as ca
import numpy as np
from scipy.integrate import solve_ivp

from ..errors import SimulationError
from .inputs import interval_inputs
from .model import ModelFunctions
from .settings import SimulationSettings

__all__ = ["integrate_radau"]


def integrate_radau(
    fns: ModelFunctions,
    p: np.ndarray,
    t: np.ndarray,
    u: np.ndarray,
    x0: np.ndarray,
    settings: SimulationSettings,
) -> np.ndarray:
    """Integrate sample interval by sample interval with Radau (tolerances from ``settings``)."""
    jac = ca.Function(
        "rhs_jacobian", [fns.x_sym, fns.u_sym, fns.p_sym], [ca.jacobian(fns.dx_expr, fns.x_sym)]
    )
    u0, u1 = interval_inputs(u)
    x = np.empty((len(t), len(x0)))
    x[0] = x0
    for k in range(len(t) - 1):
        ta, tb = t[k], t[k + 1]

        def uin(tt, k=k, ta=ta, tb=tb):
            a = (tt - ta) / (tb - ta)
            return u0[k] + a * (u1[k] - u0[k])

        sol = solve_ivp(
            lambda tt, xx, uin=uin: np.asarray(fns.rhs(xx, uin(tt), p)).ravel(),
            (ta, tb),
            x[k],
            method="Radau",
            rtol=settings.rtol,
            atol=settings.atol,
            jac=lambda tt, xx, uin=uin: np.asarray(jac(xx, uin(tt), p)),
        )
        if not sol.success:
            raise SimulationError(f"Radau failed at t = {ta:.6g} s: {sol.message}")
        x[k + 1] = sol.y[:, -1]
    return x
