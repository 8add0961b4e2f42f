"""Clutch pressure sensor."""

from __future__ import annotations

from ..assembly import Assembly
from .base import Component

__all__ = ["PressureSensor"]


class PressureSensor(Component):
    """Ideal sensor at the clutch port: ``p_sensor = p_clutch_port`` (``p_c`` unless a law
    switches the port).

    Defines ``p_sensor`` (Pa) and its time derivative ``dp_sensor`` (Pa/s); sensor
    effects (lag, transport delay) wrap both so that they compose.
    """

    name = "sensor"
    description = "clutch pressure transducer"
    PARAMETERS = ()

    def build(self, asm: Assembly) -> None:
        asm.define("p_sensor", lambda a: a["p_clutch_port"], "Pa")
        asm.define("dp_sensor", lambda a: a["dp_clutch_port"], "Pa/s")
