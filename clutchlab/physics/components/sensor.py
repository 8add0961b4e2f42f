"""Clutch pressure sensor."""

from __future__ import annotations

from ..assembly import Assembly
from .base import Component

__all__ = ["PressureSensor"]


class PressureSensor(Component):
    """Ideal sensor at the clutch port: ``p_sensor = p_c``.

    Defines ``p_sensor`` (Pa) and its time derivative ``dp_sensor`` (Pa/s); sensor
    effects (lag, transport delay) wrap both so that they compose.
    """

    name = "sensor"
    description = "clutch pressure transducer"
    PARAMETERS = ()

    def build(self, asm: Assembly) -> None:
        asm.define("p_sensor", lambda a: a.x("p_c"), "Pa")
        asm.define("dp_sensor", lambda a: a["der:p_c"], "Pa/s")
