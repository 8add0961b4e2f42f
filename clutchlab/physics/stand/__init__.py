"""The synthetic test stand: the embedded, higher-fidelity data source."""

from .overview import plot_pressure_vs_current
from .scenarios import (
    DITHER_SHAPES,
    RAMPS,
    DitherSetting,
    RampProfile,
    dither_amplitude,
    order_ramps,
)
from .stand import (
    BUILTIN_EFFECTS,
    DEFAULT_SETTINGS,
    StandConfig,
    StandRun,
    as_built_values,
    run_stand,
    truth_path,
    write_stand,
)

__all__ = [
    "BUILTIN_EFFECTS",
    "DEFAULT_SETTINGS",
    "DITHER_SHAPES",
    "RAMPS",
    "DitherSetting",
    "RampProfile",
    "StandConfig",
    "StandRun",
    "as_built_values",
    "dither_amplitude",
    "order_ramps",
    "plot_pressure_vs_current",
    "run_stand",
    "truth_path",
    "write_stand",
]
