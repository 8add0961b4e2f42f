"""Clutch pressure regulator spool valve and its feedback chamber."""

from __future__ import annotations

import math

import casadi as ca

from ..assembly import Assembly, StateSpec
from ..smooth import smooth_max0
from .base import Component, param
from .fluid import flow

__all__ = ["FeedbackChamber", "RegulatorSpool"]

_C = "reg"

#: Stiffness of the spool end stops (N/m) and smoothing of the metering edges (m).
STOP_STIFFNESS = 2.0e5
EDGE_EPS = 10e-6


class RegulatorSpool(Component):
    """Regulator spool: ``m ẍ = A_pil p_a + F_0 − k x − A_fb p_fb − c v − F_fric + F_stop``.

    Positive ``x`` meters line → clutch, negative clutch → exhaust (prime).
    Flow forces, leakage and friction laws beyond Coulomb are effects.
    """

    name = _C
    description = "clutch pressure regulator spool"
    PARAMETERS = (
        param(_C, "d_pil", "mm", 12.0, 6.0, 20.0, "pilot (VFS) land diameter"),
        param(_C, "d_fb", "mm", 9.5, 5.0, 16.0, "feedback land diameter"),
        param(_C, "m", "g", 20.0, 5.0, 60.0, "spool mass"),
        param(_C, "k", "N/mm", 15.0, 1.0, 50.0, "spring rate"),
        param(
            _C, "F0", "N", -2.0, -20.0, 20.0, "spring force at x = 0 (+ opens)", transform="linear"
        ),
        param(_C, "c", "N·s/m", 8.0, 0.5, 50.0, "viscous damping"),
        param(_C, "F_c", "N", 1.0, 0.01, 5.0, "Coulomb friction"),
        param(_C, "v_s", "mm/s", 2.0, 0.1, 20.0, "velocity scale of the smooth friction sign"),
        param(_C, "w", "mm", 15.0, 2.0, 35.0, "metering port width (area gradient)"),
        param(_C, "x_max", "mm", 1.5, 0.5, 4.0, "spool travel to the end stops"),
        param(
            _C,
            "G_leak",
            "mm³/(s·bar)",
            10.0,
            0.5,
            500.0,
            "clearance leakage clutch → exhaust at reference viscosity",
        ),
    )

    def build(self, asm: Assembly) -> None:
        x = asm.state(StateSpec("x_r", "mm", -0.5, "regulator spool position (+ opens line)", _C))
        v = asm.state(StateSpec("v_r", "mm/s", 0.0, "regulator spool velocity", _C))
        a_pil = lambda a: math.pi / 4.0 * a.p("reg_d_pil") ** 2  # noqa: E731
        a_fb = lambda a: math.pi / 4.0 * a.p("reg_d_fb") ** 2  # noqa: E731

        asm.define("A_reg_in", lambda a: a.p("reg_w") * smooth_max0(x, EDGE_EPS), "m²")
        asm.define("A_reg_out", lambda a: a.p("reg_w") * smooth_max0(-x, EDGE_EPS), "m²")
        asm.define("p_supply", lambda a: a["p_line"], "Pa")
        asm.define("Q_reg_in", lambda a: flow(a, a["A_reg_in"], a["p_supply"] - a.x("p_c")), "m³/s")
        asm.define(
            "Q_reg_out", lambda a: flow(a, a["A_reg_out"], a.x("p_c") - a["p_prime"]), "m³/s"
        )
        asm.define(
            "Q_reg_leak",
            lambda a: a.p("reg_G_leak") / a["visc_ratio"] * (a.x("p_c") - a["p_prime"]),
            "m³/s",
        )
        asm.define("F_reg_friction", lambda a: a.p("reg_F_c") * ca.tanh(v / a.p("reg_v_s")), "N")

        def f_stop(a):
            xm = a.p("reg_x_max")
            return -STOP_STIFFNESS * (
                smooth_max0(x - xm, EDGE_EPS) - smooth_max0(-xm - x, EDGE_EPS)
            )

        # The pilot pressure the spool's pilot face sees (a flexible law may lag it).
        asm.define("p_reg_pilot", lambda a: a.x("p_a"), "Pa")
        asm.define(
            "F_reg",
            lambda a: (
                a_pil(a) * a["p_reg_pilot"]
                + a.p("reg_F0")
                - a.p("reg_k") * x
                - a_fb(a) * a.x("p_fb")
                - a.p("reg_c") * a["visc_ratio"] * v
                - a["F_reg_friction"]
                + f_stop(a)
            ),
            "N",
        )
        asm.define("der:x_r", lambda a: v, "m/s")
        asm.define("der:v_r", lambda a: a["F_reg"] / a.p("reg_m"), "m/s²")


class FeedbackChamber(Component):
    """Regulator feedback chamber, fed from the clutch through a damping orifice.

    When the latch valve opens it exhausts this chamber, the feedback force
    vanishes and the regulator opens fully: clutch pressure goes to line.
    """

    name = "fb"
    description = "regulator feedback chamber and damping orifice"
    PARAMETERS = (
        param("fb", "d_orf", "mm", 0.8, 0.3, 2.0, "damping orifice clutch → feedback"),
        param("fb", "V", "cm³", 0.5, 0.05, 3.0, "feedback chamber oil volume"),
    )

    def build(self, asm: Assembly) -> None:
        p = asm.state(StateSpec("p_fb", "bar", 0.5, "regulator feedback pressure", "fb"))
        asm.define(
            "Q_fb_orf",
            lambda a: flow(a, math.pi / 4.0 * a.p("fb_d_orf") ** 2, a.x("p_c") - p),
            "m³/s",
        )

        def der(a):
            a_fb = math.pi / 4.0 * a.p("reg_d_fb") ** 2
            q = a["Q_fb_orf"] - a["Q_latch_exh"] + a_fb * a.x("v_r")
            return a["beta:p_fb"] / a.p("fb_V") * q

        asm.define("der:p_fb", der, "Pa/s")
