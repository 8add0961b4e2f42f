"""Sensor effects: first-order lag and transport delay of the pressure reading."""

from __future__ import annotations

from ..assembly import Assembly, StateSpec
from ..components.base import param
from .base import Effect, add_first_order_lag

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
    FIT = ("slag_tau",)

    def apply(self, asm: Assembly) -> None:
        state = StateSpec("e_slag", "bar", 0.0, "sensor lag deficit", self.name)
        add_first_order_lag(asm, "p_sensor", "dp_sensor", state, "slag_kappa", "slag_tau")


class TransportDelay(Effect):
    """Transport delay ``y ≈ p(t − d)``: ``y = p − d·s·H(s)·p`` with a 2nd-order Padé filter.

    ``H(s) = 1 / (1 + s d₀/2 + (s d₀)²/12)``; for ``d = d₀`` this is the (2,2) Padé
    approximant of the delay, for ``d → 0`` it vanishes exactly. The filter states
    are ``q = H·p`` (bar) and ``r = dq/dt`` (bar/s), so ``y = p − d·r``.

    A fit frees both ``d`` and ``d₀``: with ``d₀`` held at its default, ``y`` is only the
    first-order expansion ``p − d·dp/dt`` of a delay much longer than ``d₀`` and cannot
    represent it. ``d₀`` has no effect at ``d = 0``; the score test of the effect treats it
    as a nuisance parameter, like a lag's time constant.
    """

    name = "transport_delay"
    description = "transport delay of the pressure reading (sampling, hose, DAQ)"
    signature = "residual ∝ −d·dp/dt, lagged cross-correlation peak at a positive lag"
    PARAMETERS = (
        param("delay", "d", "ms", 3.0, 0.0, 30.0, "delay", "linear"),
        param("delay", "d0", "ms", 3.0, 0.5, 30.0, "delay of the Padé filter"),
    )
    STRENGTH = ("delay_d",)
    FIT = ("delay_d", "delay_d0")

    def apply(self, asm: Assembly) -> None:
        q = asm.state(StateSpec("q_delay", "bar", 0.5, "Padé-filtered pressure", self.name))
        r = asm.state(StateSpec("r_delay", "bar/s", 0.0, "its rate", self.name))
        asm.tap("p_sensor", "p_sensor_in:delay")
        asm.define("der:q_delay", lambda a: r, "Pa/s")
        asm.define(
            "der:r_delay",
            lambda a: (
                (a["p_sensor_in:delay"] - q - a.p("delay_d0") / 2.0 * r)
                / (a.p("delay_d0") ** 2 / 12.0)
            ),
            "Pa/s²",
        )
        asm.wrap("p_sensor", lambda a, prev: prev - a.p("delay_d") * r)
        asm.wrap("dp_sensor", lambda a, prev: prev - a.p("delay_d") * a["der:r_delay"])
