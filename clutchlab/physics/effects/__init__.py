"""The effect library: named, switchable augmentations of the circuit model.

Each effect has its own parameters (default = typical strength when on, with
bounds and unit), a set of *strength* parameters that switch it off exactly at
zero, and a one-line residual signature.
"""

from __future__ import annotations

from ...errors import ModelError
from .base import Effect
from .flexible import FreeLatchThresholds, MonotoneForceCorrection, PlayHysteresis
from .friction import DitherFrictionReduction, StribeckFriction
from .hydraulic import (
    AccumulatorSpringNonlinearity,
    AirEntrainment,
    FlowForce,
    SpoolLeakage,
    SupplyDroop,
)
from .latch import LatchThresholdDrift
from .magnetic import EddyCurrentLag, MagneticHysteresis
from .sensor import SensorLag, TransportDelay
from .thermal import OilTemperature

__all__ = [
    "EFFECTS",
    "FLEXIBLE_LAWS",
    "AccumulatorSpringNonlinearity",
    "AirEntrainment",
    "DitherFrictionReduction",
    "EddyCurrentLag",
    "Effect",
    "FlowForce",
    "FreeLatchThresholds",
    "LatchThresholdDrift",
    "MagneticHysteresis",
    "MonotoneForceCorrection",
    "OilTemperature",
    "PlayHysteresis",
    "SensorLag",
    "SpoolLeakage",
    "StribeckFriction",
    "SupplyDroop",
    "TransportDelay",
    "effect_table",
    "make_effect",
]

#: Registry: effect name -> class.
EFFECTS: dict[str, type[Effect]] = {
    cls.name: cls
    for cls in (
        StribeckFriction,
        DitherFrictionReduction,
        FlowForce,
        SpoolLeakage,
        OilTemperature,
        SupplyDroop,
        SensorLag,
        TransportDelay,
        MagneticHysteresis,
        EddyCurrentLag,
        LatchThresholdDrift,
        AirEntrainment,
        AccumulatorSpringNonlinearity,
        MonotoneForceCorrection,
        PlayHysteresis,
        FreeLatchThresholds,
    )
}

#: The flexible component laws among them (identity at their defaults; no stand uses them).
FLEXIBLE_LAWS: tuple[str, ...] = (
    MonotoneForceCorrection.name,
    PlayHysteresis.name,
    FreeLatchThresholds.name,
)


def make_effect(name: str) -> Effect:
    """Instantiate the library effect called ``name``.

    Raises
    ------
    ModelError
        If there is no such effect; the message lists the known ones.
    """
    try:
        return EFFECTS[name.strip()]()
    except KeyError:
        known = ", ".join(sorted(EFFECTS))
        raise ModelError(f"unknown effect {name!r}; known effects: {known}") from None


def effect_table() -> list[dict[str, str]]:
    """Name, description, residual signature and parameters of every library effect."""
    return [
        {
            "name": cls.name,
            "description": cls.description,
            "signature": cls.signature,
            "strength": ", ".join(cls.STRENGTH),
            "parameters": ", ".join(f"{p.name} [{p.unit}]" for p in cls.PARAMETERS),
        }
        for cls in EFFECTS.values()
    ]
