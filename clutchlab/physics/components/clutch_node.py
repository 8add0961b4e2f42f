"""Clutch node: clutch line, dead-headed sensor port and the clutch accumulator."""

from __future__ import annotations

from ..assembly import Assembly, StateSpec
from .accumulator import accumulator_compliance, accumulator_parameters
from .base import Component, param

__all__ = ["ClutchNode"]

_C = "cacc"


class ClutchNode(Component):
    """``dp_c/dt = (Q_in − Q_out − Q_fb − Q_leak + ΣQ_extra) / (V/β + C_acc(p_c))``.

    The clutch accumulator stands in for the clutch's own compliance on the stand.
    ``Q_clutch_extra`` is a sum effects add flows to (positive into the node).
    """

    name = _C
    description = "clutch line and clutch accumulator"
    PARAMETERS = (
        *accumulator_parameters(_C, 20.0, 40.0, 1.0, 15.0, "clutch accumulator"),
        param(_C, "V", "cm³", 15.0, 2.0, 100.0, "clutch line oil volume"),
    )

    def build(self, asm: Assembly) -> None:
        p = asm.state(StateSpec("p_c", "bar", 0.5, "clutch pressure", _C))
        asm.define("acc_kappa:cacc", lambda a: 0.0, "-")
        asm.add_term("Q_clutch_extra", lambda a: 0.0)

        def der(a):
            c = a.p("cacc_V") / a["beta:p_c"] + accumulator_compliance(a, _C, p)
            q = (
                a["Q_reg_in"]
                - a["Q_reg_out"]
                - a["Q_fb_orf"]
                - a["Q_reg_leak"]
                + a["Q_clutch_extra"]
            )
            return q / c

        asm.define("der:p_c", der, "Pa/s")
