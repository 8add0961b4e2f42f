"""Solenoid effects: magnetic hysteresis and eddy-current lag of the VFS force."""

from __future__ import annotations

import casadi as ca

from ..assembly import Assembly, StateSpec
from ..components.base import param
from .base import Effect, add_first_order_lag

__all__ = ["EddyCurrentLag", "MagneticHysteresis"]


class MagneticHysteresis(Effect):
    """Direction-dependent magnetic force (smooth Bouc–Wen play of the current).

    State ``h ∈ [−1, 1]``: ``dh/dt = (di/dt / i_w)(1 − h·tanh(di/dt / r))``; the force is
    ``F_mag − H·h`` (less force rising, more falling). Dither drives minor loops.
    """

    name = "vfs_magnetic_hysteresis"
    description = "VFS magnetic hysteresis"
    signature = (
        "offset of opposite sign on rising and falling current (sign of dI/dt), "
        "independent of ramp rate, reduced by dither"
    )
    PARAMETERS = (
        param("mhys", "H", "N", 0.3, 0.0, 3.0, "hysteresis force amplitude", "linear"),
        param("mhys", "i_w", "mA", 30.0, 2.0, 300.0, "current travel to saturate the play"),
    )
    STRENGTH = ("mhys_H",)

    def apply(self, asm: Assembly) -> None:
        h = asm.state(StateSpec("h_mag", "-", 0.0, "magnetic hysteresis play state", self.name))

        def dh(a):
            di = a["di_coil"]
            return di / a.p("mhys_i_w") * (1.0 - h * ca.tanh(di / 1e-2))

        asm.define("der:h_mag", dh, "1/s")
        asm.wrap("F_mag", lambda a, prev: prev - a.p("mhys_H") * h)
        asm.wrap("dF_mag", lambda a, prev: prev - a.p("mhys_H") * a["der:h_mag"])


class EddyCurrentLag(Effect):
    """First-order lag of the magnetic force behind the current (eddy currents).

    ``F = F_mag − κ e`` with ``de/dt = dF_mag/dt − e/τ``: for κ = 1 exactly the
    first-order lag ``τ dF/dt = F_mag − F``; for κ = 0 no effect.
    """

    name = "eddy_current_lag"
    description = "eddy-current lag of the VFS magnetic force"
    signature = "lag growing with |dI/dt| (ramp rate); attenuated effective dither"
    PARAMETERS = (
        param("eddy", "kappa", "-", 1.0, 0.0, 1.0, "lag strength", "linear"),
        param("eddy", "tau", "ms", 3.0, 0.1, 50.0, "eddy-current time constant"),
    )
    STRENGTH = ("eddy_kappa",)
    FIT = ("eddy_tau",)

    def apply(self, asm: Assembly) -> None:
        state = StateSpec("e_eddy", "N", 0.0, "eddy-current force deficit", self.name)
        add_first_order_lag(asm, "F_mag", "dF_mag", state, "eddy_kappa", "eddy_tau")
