"""Library effects as the zoo's plants carry them, and the reasons a plant refuses one.

A plant carries a library effect through parameters of its *own* equations (named
alike in every plant, zero when the effect is off); nothing of the fit model's effect
code is used. The library's effect names are listed here as plain strings so that the
zoo imports nothing from the fit model; a test checks the list against the library.
"""

from __future__ import annotations

from .base import PlantEffect

__all__ = ["LIBRARY_EFFECTS", "standard_effects", "standard_refusals"]

#: Names of the fit model's effect library (checked against it by the tests).
LIBRARY_EFFECTS: tuple[str, ...] = (
    "stribeck_friction",
    "dither_friction_reduction",
    "flow_force",
    "spool_leakage",
    "oil_temperature",
    "supply_droop",
    "sensor_lag",
    "transport_delay",
    "vfs_magnetic_hysteresis",
    "eddy_current_lag",
    "latch_threshold_drift",
    "air_entrainment",
    "accumulator_spring_nonlinearity",
)

#: Parameter ranges of the effects every plant carries.
_RANGES: dict[str, dict[str, tuple[float, float]]] = {
    "oil_temperature": {"temp_visc": (0.6, 1.0), "temp_leak": (0.02, 0.04)},
    "supply_droop": {"line_coupling": (0.3, 0.6), "droop_s": (0.02, 0.05)},
    "spool_leakage": {"leak": (0.001, 0.002)},
    "sensor_lag": {"tau_lag_ms": (8.0, 15.0)},
    "transport_delay": {"delay_ms": (3.0, 8.0)},
}

_DEFAULT_HOW = {
    "sensor_lag": "an extra first-order lag of the transducer",
    "transport_delay": "a delay of the logged pressure",
}

_DEFAULT_REFUSAL = {
    "stribeck_friction": "its friction law is its own; a second one on the same spool is not "
    "a variant of this circuit",
    "dither_friction_reduction": "dither reduces friction here through the resolved spool "
    "motion; a separate law would count it twice",
    "flow_force": "its regulator is written in pressure-equivalent form, without port flows",
    "vfs_magnetic_hysteresis": "its magnetic law is its own",
    "eddy_current_lag": "its magnetic law is its own",
    "latch_threshold_drift": "its latch law is its own",
    "air_entrainment": "its fill compliance is its own",
    "accumulator_spring_nonlinearity": "its fill compliance is its own",
}


def standard_effects(**how: str) -> dict[str, PlantEffect]:
    """The effects a plant carries: ``name=description`` of how it enters its equations.

    ``sensor_lag`` and ``transport_delay`` are carried by every plant (the bench's
    transducer), with a default description.
    """
    hows = _DEFAULT_HOW | how
    unknown = sorted(set(hows) - set(_RANGES))
    if unknown:
        raise ValueError(f"no parameter ranges for plant effect(s) {unknown}")
    return {name: PlantEffect(hows[name], _RANGES[name]) for name in hows}


def standard_refusals(**reasons: str) -> dict[str, str]:
    """Reasons for the library effects a plant does not carry (defaults, then overrides)."""
    return _DEFAULT_REFUSAL | reasons
