"""Clutch node: clutch line, dead-headed sensor port and the clutch accumulator."""

from __future__ import annotations

from ..assembly import Assembly, StateSpec
from .accumulator import accumulator_parameters, declare_accumulator_node, node_compliance
from .base import Component

__all__ = ["ClutchNode"]

_C = "cacc"


class ClutchNode(Component):
    """``dp_c/dt = (Q_in − Q_out − Q_fb − Q_leak + ΣQ_extra) / (V/β + C_acc(p_c))``.

    The clutch accumulator stands in for the clutch's own compliance on the stand.
    ``Q_clutch_extra`` is a sum effects add flows to (positive into the node).
    """

    name = _C
    description = "clutch line and clutch accumulator"
    PARAMETERS = accumulator_parameters(
        _C, 20.0, 40.0, 1.0, 15.0, "clutch accumulator", 15.0, "clutch line"
    )

    def build(self, asm: Assembly) -> None:
        p = asm.state(StateSpec("p_c", "bar", 0.5, "clutch pressure", _C))
        declare_accumulator_node(asm, _C)
        asm.add_term("Q_clutch_extra", lambda a: 0.0)

        def der(a):
            q = (
                a["Q_reg_in"]
                - a["Q_reg_out"]
                - a["Q_fb_orf"]
                - a["Q_reg_leak"]
                + a["Q_clutch_extra"]
            )
            return q / node_compliance(a, _C, "p_c", p)

        asm.define("der:p_c", der, "Pa/s")
        # The pressure at the clutch port (the sensor's tapping) and its rate; a flexible
        # latch law may connect the port to line pressure instead.
        asm.define("p_clutch_port", lambda a: a.x("p_c"), "Pa")
        asm.define("dp_clutch_port", lambda a: a["der:p_c"], "Pa/s")
