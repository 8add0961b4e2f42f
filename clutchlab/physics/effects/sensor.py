"""Sensor effects: first-order lag and transport delay of the pressure reading."""

from __future__ import annotations

from ..assembly import Assembly, StateSpec
from ..components.base import param
from .base import Effect

__all__ = ["SensorLag", "TransportDelay"]


class SensorLag(Effect):
    """First-order sensor lag ``y = p − κ e``, ``de/dt = dp/dt − e/τ`` (κ = 1: exact lag)."""

    name = "sensor_lag"
    description = "first-order lag of the pressure transducer / hose"
    signature = "residual ∝ −τ·dp/dt: largest on steep pressure changes and the latch snap"
    PARAMETERS = (
        param("slag", "kappa", "-", 1.0, 0.0, 1.0, "lag strength", "linear"),
        param("slag", "tau", "ms", 5.0, 0.1, 100.0, "sensor time constant"),
    )
    STRENGTH = ("slag_kappa",)

    def apply(self, asm: Assembly) -> None:
        e = asm.state(StateSpec("e_slag", "bar", 0.0, "sensor lag deficit", self.name))
        asm.tap("dp_sensor", "dp_sensor_in:slag")
        asm.define("der:e_slag", lambda a: a["dp_sensor_in:slag"] - e / a.p("slag_tau"), "Pa/s")
        asm.wrap("p_sensor", lambda a, prev: prev - a.p("slag_kappa") * e)
        asm.wrap(
            "dp_sensor", lambda a, prev: prev - a.p("slag_kappa") * (prev - e / a.p("slag_tau"))
        )


class TransportDelay(Effect):
    """Transport delay ``y ≈ p(t − d)``: ``y = p − d·H(s)·ṗ`` with a 2nd-order Padé filter.

    ``H(s) = 1 / (1 + s d₀/2 + (s d₀)²/12)``; for ``d = d₀`` this is the (2,2) Padé
    approximant of the delay, for ``d → 0`` it vanishes exactly.
    """

    name = "transport_delay"
    description = "transport delay of the pressure reading (sampling, hose, DAQ)"
    signature = "residual ∝ −d·dp/dt, lagged cross-correlation peak at a positive lag"
    PARAMETERS = (
        param("delay", "d", "ms", 3.0, 0.0, 30.0, "delay", "linear"),
        param("delay", "d0", "ms", 3.0, 0.5, 30.0, "delay of the Padé filter"),
    )
    STRENGTH = ("delay_d",)

    def apply(self, asm: Assembly) -> None:
        # H(s) realised as dw/dt = z, (d0²/12) dz/dt = dp/dt − w − (d0/2) z: w = H·ṗ.
        w = asm.state(StateSpec("w_delay", "bar/s", 0.0, "Padé-filtered pressure rate", self.name))
        z = asm.state(StateSpec("z_delay", "bar/s²", 0.0, "Padé filter second state", self.name))

        def d0(a):
            return a.p("delay_d0")

        asm.tap("dp_sensor", "dp_sensor_in:delay")
        asm.define("der:w_delay", lambda a: z, "Pa/s²")
        asm.define(
            "der:z_delay",
            lambda a: (a["dp_sensor_in:delay"] - w - d0(a) / 2.0 * z) / (d0(a) ** 2 / 12.0),
            "Pa/s³",
        )
        asm.wrap("p_sensor", lambda a, prev: prev - a.p("delay_d") * w)
        asm.wrap("dp_sensor", lambda a, prev: prev - a.p("delay_d") * z)
