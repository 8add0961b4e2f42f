"""Variable-force solenoid: magnetic force, armature/spool, pilot feedback, output chamber."""

from __future__ import annotations

import math

import casadi as ca

from ..assembly import Assembly, StateSpec
from ..smooth import smooth_max0
from .base import Component, param
from .fluid import flow

__all__ = ["VariableForceSolenoid"]

_C = "vfs"


class VariableForceSolenoid(Component):
    """Normally-low VFS: a small pressure regulator whose set force is magnetic.

    ``m ẍ = F_mag(i) − F_pre − k x − A_fb p_vo − c v − F_fric(v)``;
    ``F_mag = K_m · i · tanh(i / i_knee)``. Positive ``x`` opens line → output,
    negative opens output → exhaust (prime). The output chamber ``p_vo`` feeds the
    VFS accumulator node through a damping orifice.
    """

    name = _C
    description = "variable-force solenoid valve (normally low)"
    PARAMETERS = (
        param(
            _C,
            "K_m",
            "N/A",
            14.0,
            5.0,
            30.0,
            "magnetic force gain at saturation, newton per ampere",
        ),
        param(_C, "i_knee", "mA", 200.0, 50.0, 500.0, "current at the knee of the force curve"),
        param(_C, "F_pre", "N", 1.0, 0.1, 5.0, "spring preload (closing)"),
        param(_C, "k", "N/mm", 2.0, 0.5, 10.0, "spring rate"),
        param(_C, "m", "g", 8.0, 2.0, 30.0, "armature + spool mass"),
        param(_C, "c", "N·s/m", 20.0, 1.0, 80.0, "viscous damping (oil-filled armature)"),
        param(_C, "F_c", "N", 0.05, 0.005, 1.0, "Coulomb friction"),
        param(_C, "v_s", "mm/s", 1.0, 0.1, 10.0, "velocity scale of the smooth friction sign"),
        param(_C, "d_fb", "mm", 4.0, 2.0, 8.0, "pilot feedback diameter"),
        param(_C, "w", "mm", 2.0, 0.5, 10.0, "metering port width (area gradient)"),
        param(_C, "V", "cm³", 0.3, 0.05, 2.0, "output chamber oil volume"),
        param(_C, "d_orf", "mm", 0.45, 0.2, 1.5, "damping orifice to the VFS accumulator"),
        param(
            _C,
            "G_leak",
            "mm³/(s·bar)",
            20.0,
            1.0,
            500.0,
            "laminar leakage output → exhaust at reference viscosity",
        ),
    )

    def build(self, asm: Assembly) -> None:
        x = asm.state(StateSpec("x_v", "mm", -0.5, "VFS spool position (+ opens supply)", _C))
        v = asm.state(StateSpec("v_v", "mm/s", 0.0, "VFS spool velocity", _C))
        p = asm.state(StateSpec("p_vo", "bar", 0.5, "VFS output chamber pressure", _C))

        def f_mag(a):
            i = a["i_coil"]
            return a.p("vfs_K_m") * i * ca.tanh(i / a.p("vfs_i_knee"))

        def df_mag(a):
            i, ik, km = a["i_coil"], a.p("vfs_i_knee"), a.p("vfs_K_m")
            th = ca.tanh(i / ik)
            return km * (th + i / ik * (1.0 - th * th)) * a["di_coil"]

        asm.define("F_mag", f_mag, "N")
        asm.define("dF_mag", df_mag, "N/s")
        asm.define("F_vfs_friction", lambda a: a.p("vfs_F_c") * ca.tanh(v / a.p("vfs_v_s")), "N")
        a_fb = lambda a: math.pi / 4.0 * a.p("vfs_d_fb") ** 2  # noqa: E731
        asm.define(
            "F_vfs",
            lambda a: (
                a["F_mag"]
                - a.p("vfs_F_pre")
                - a.p("vfs_k") * x
                - a_fb(a) * p
                - a.p("vfs_c") * a["visc_ratio"] * v
                - a["F_vfs_friction"]
            ),
            "N",
        )
        eps = 2e-6
        asm.define(
            "Q_vfs_sup",
            lambda a: flow(a, a.p("vfs_w") * smooth_max0(x, eps), a["p_line"] - p),
            "m³/s",
        )
        asm.define(
            "Q_vfs_exh",
            lambda a: flow(a, a.p("vfs_w") * smooth_max0(-x, eps), p - a["p_prime"]),
            "m³/s",
        )
        asm.define(
            "Q_vfs_orf",
            lambda a: flow(a, math.pi / 4.0 * a.p("vfs_d_orf") ** 2, p - a.x("p_a")),
            "m³/s",
        )
        asm.define(
            "Q_vfs_leak", lambda a: a.p("vfs_G_leak") / a["visc_ratio"] * (p - a["p_prime"]), "m³/s"
        )
        asm.define("der:x_v", lambda a: v, "m/s")
        asm.define("der:v_v", lambda a: a["F_vfs"] / a.p("vfs_m"), "m/s²")
        asm.define(
            "der:p_vo",
            lambda a: (
                a["beta:p_vo"]
                / a.p("vfs_V")
                * (a["Q_vfs_sup"] - a["Q_vfs_exh"] - a["Q_vfs_orf"] - a["Q_vfs_leak"])
            ),
            "Pa/s",
        )
