"""Friction effects on the regulator spool."""

from __future__ import annotations

import casadi as ca

from ..assembly import Assembly
from ..components.base import param
from .base import Effect

__all__ = ["DitherFrictionReduction", "StribeckFriction"]


class StribeckFriction(Effect):
    """Breakaway (static) friction above the Coulomb level, decaying with speed."""

    name = "stribeck_friction"
    description = "Stribeck / breakaway friction of the regulator spool"
    signature = (
        "steps and overshoot where the spool reverses (sign changes of dI/dt); "
        "hysteresis independent of ramp rate"
    )
    PARAMETERS = (
        param("strib", "dF", "N", 1.0, 0.0, 10.0, "breakaway force above Coulomb", "linear"),
        param("strib", "v", "mm/s", 5.0, 0.2, 50.0, "Stribeck velocity"),
    )
    STRENGTH = ("strib_dF",)

    def apply(self, asm: Assembly) -> None:
        def wrap(a, prev):
            v = a.x("v_r")
            return prev + a.p("strib_dF") * ca.exp(-((v / a.p("strib_v")) ** 2)) * ca.tanh(
                v / a.p("reg_v_s")
            )

        asm.wrap("F_reg_friction", wrap)


class DitherFrictionReduction(Effect):
    """Effective Coulomb friction lowered by dither (micro-motion breaks stiction)."""

    name = "dither_friction_reduction"
    description = "dither-amplitude-dependent reduction of regulator friction"
    signature = "hysteresis width that shrinks with dither amplitude; differs between dither shapes"
    PARAMETERS = (
        param("dfr", "kappa", "-", 2.0, 0.0, 20.0, "friction reduction strength", "linear"),
        param("dfr", "A_ref", "mA", 100.0, 10.0, 500.0, "reference dither amplitude"),
    )
    STRENGTH = ("dfr_kappa",)

    def apply(self, asm: Assembly) -> None:
        asm.wrap(
            "F_reg_friction",
            lambda a, prev: (
                prev / (1.0 + a.p("dfr_kappa") * a.u["dither_amp_mA"] * 1e-3 / a.p("dfr_A_ref"))
            ),
        )
