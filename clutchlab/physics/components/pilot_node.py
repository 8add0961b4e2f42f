"""VFS accumulator node: the pilot pressure seen by the regulator and the latch valve."""

from __future__ import annotations

import math

from ..assembly import Assembly, StateSpec
from .accumulator import accumulator_parameters, declare_accumulator_node, node_compliance
from .base import Component

__all__ = ["PilotNode"]

_C = "vacc"


class PilotNode(Component):
    """VFS accumulator and the pilot chambers of regulator and latch.

    ``dp_a/dt = (Q_vfs_orf − A_pil·v_r − A_latch·ẋ_latch) / (V/β + C_acc(p_a))``.
    """

    name = _C
    description = "VFS accumulator and pilot line"
    PARAMETERS = accumulator_parameters(
        _C, 12.0, 12.0, 1.0, 12.0, "VFS accumulator", 2.0, "pilot line"
    )

    def build(self, asm: Assembly) -> None:
        p = asm.state(StateSpec("p_a", "bar", 0.5, "pilot (VFS accumulator) pressure", _C))
        declare_accumulator_node(asm, _C)

        def der(a):
            a_pil = math.pi / 4.0 * a.p("reg_d_pil") ** 2
            q = a["Q_vfs_orf"] - a_pil * a.x("v_r") - a["V_latch_rate"]
            return q / node_compliance(a, _C, "p_a", p)

        asm.define("der:p_a", der, "Pa/s")
