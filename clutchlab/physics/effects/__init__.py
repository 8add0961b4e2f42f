"""The effect library: named, switchable augmentations of the circuit model.

Each effect has its own parameters (default = typical strength when on, with
bounds and unit), a set of *strength* parameters that switch it off exactly at
zero, and a one-line residual signature.
"""

from __future__ import annotations

from typing import Any

from ...errors import ModelError
from .base import Effect
from .flexible import (
    FreeLatchThresholds,
    LatchDitherBand,
    LatchLineSelect,
    LatchLineThreshold,
    LatchOnLag,
    LatchPilotLag,
    LatchRateBand,
    MonotoneForceCorrection,
    PlayHysteresis,
    RegulatorPilotLag,
    dither_band_terms,
    rate_band_terms,
)
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
    "LatchDitherBand",
    "LatchLineSelect",
    "LatchLineThreshold",
    "LatchOnLag",
    "LatchPilotLag",
    "LatchRateBand",
    "LatchThresholdDrift",
    "MagneticHysteresis",
    "MonotoneForceCorrection",
    "OilTemperature",
    "PlayHysteresis",
    "RegulatorPilotLag",
    "SensorLag",
    "SpoolLeakage",
    "StribeckFriction",
    "SupplyDroop",
    "TransportDelay",
    "dither_band_terms",
    "effect_names",
    "effect_of_parameter",
    "effect_table",
    "make_effect",
    "missing_effect",
    "rate_band_terms",
]

#: The flexible component laws (identity at their defaults; no stand uses them).
FLEXIBLE_LAWS: dict[str, type[Effect]] = {
    cls.name: cls
    for cls in (
        MonotoneForceCorrection,
        PlayHysteresis,
        FreeLatchThresholds,
        LatchLineSelect,
        RegulatorPilotLag,
        LatchOnLag,
        LatchPilotLag,
        LatchDitherBand,
        LatchRateBand,
        LatchLineThreshold,
    )
}


class _EffectRegistry(dict):
    """Effect name -> class. Iterating it (``in``, ``len``, listing) gives the library's
    physical effects; looking a flexible law up by name (``EFFECTS[name]``) finds it too,
    so a model with flexible laws is built, fitted and saved like one with effects,
    while the effect library (discovery candidates, ``clutchlab effects``) stays the
    physical one."""

    def __missing__(self, name: str) -> type[Effect]:
        try:
            return FLEXIBLE_LAWS[name]
        except KeyError:
            raise KeyError(name) from None


#: Registry: effect name -> class (library effects; flexible laws by name lookup).
EFFECTS: dict[str, type[Effect]] = _EffectRegistry(
    (cls.name, cls)
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
    )
)


def effect_names(value: Any, where: str = "effects") -> tuple[str, ...]:
    """Effect names given as one name (a string) or a list of names, checked against the library.

    Parameters
    ----------
    value : str or sequence of str
        ``"sensor_lag"`` (one effect; a comma-separated string is split) or
        ``["sensor_lag", "flow_force"]``.
    where : str
        How messages name the setting.

    Returns
    -------
    tuple of str
        The names, stripped, in the given order.

    Raises
    ------
    ModelError
        For a value of another type (naming it) or unknown names (listing the known ones).
    """
    if isinstance(value, str):
        names = [v.strip() for v in value.split(",") if v.strip()]
    elif isinstance(value, list | tuple) and all(isinstance(v, str) for v in value):
        names = [v.strip() for v in value]
    else:
        raise ModelError(
            f"{where}: expected an effect name or a list of effect names, got "
            f"{type(value).__name__} {value!r:.60}"
        )
    unknown = [n for n in names if n not in EFFECTS and n not in FLEXIBLE_LAWS]
    if unknown:
        known = ", ".join(sorted(EFFECTS))
        laws = ", ".join(FLEXIBLE_LAWS)
        what = "unknown effect" + ("s " if len(unknown) > 1 else " ")
        raise ModelError(
            f"{where}: {what}{', '.join(map(repr, unknown))}; known effects: {known}; "
            f"flexible laws: {laws}"
        )
    return tuple(names)


def effect_of_parameter(name: str) -> str | None:
    """The effect (or flexible law) that declares the parameter ``name``, or None.

    A model without that effect does not have the parameter; messages about an unknown
    parameter name the effect to switch on.
    """
    for cls in (*EFFECTS.values(), *FLEXIBLE_LAWS.values()):
        if any(p.name == name for p in cls.PARAMETERS):
            return cls.name
    return None


def missing_effect(name: str) -> tuple[str, str] | None:
    """``(effect, text)`` when ``name`` is a parameter of an effect (or flexible law): the
    text ``"belongs to the effect 'E', which the model does not have"``, which messages about
    an unknown parameter follow with how to add the effect where they are given; else None.
    """
    owner = effect_of_parameter(name)
    if owner is None:
        return None
    return owner, f"belongs to the effect {owner!r}, which the model does not have"


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
        laws = ", ".join(FLEXIBLE_LAWS)
        raise ModelError(
            f"unknown effect {name!r}; known effects: {known}; flexible laws: {laws}"
        ) from None


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
