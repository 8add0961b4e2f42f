"""Latch effects: threshold drift and extra hysteresis."""

from __future__ import annotations

import math

from ..assembly import Assembly
from ..components.base import param
from .base import Effect

__all__ = ["LatchThresholdDrift"]


class LatchThresholdDrift(Effect):
    """Shifted latch-on and latch-off pilot pressures (spring set, wear, contamination).

    Adds ``−A1·Δp_on·(1 − λ) − A2·Δp_off·λ`` to the latch force: the closed valve
    opens ``Δp_on`` later, the open valve closes ``Δp_off`` later.
    """

    name = "latch_threshold_drift"
    description = "latch hysteresis / threshold drift"
    signature = "large residual in the current band between modelled and true latch-on/off"
    PARAMETERS = (
        param("ldrift", "dp_on", "bar", 0.5, -3.0, 3.0, "latch-on threshold shift", "linear"),
        param("ldrift", "dp_off", "bar", -0.4, -3.0, 3.0, "latch-off threshold shift", "linear"),
    )
    STRENGTH = ("ldrift_dp_on", "ldrift_dp_off")

    def apply(self, asm: Assembly) -> None:
        def wrap(a, prev):
            a1 = math.pi / 4.0 * a.p("latch_d1") ** 2
            a2 = math.pi / 4.0 * a.p("latch_d2") ** 2
            lam = a.x("latch")
            return prev - a1 * a.p("ldrift_dp_on") * (1.0 - lam) - a2 * a.p("ldrift_dp_off") * lam

        asm.wrap("latch_F_net", wrap)
