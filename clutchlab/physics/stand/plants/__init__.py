"""The plant zoo: reference clutch circuits written independently of the fit model.

Each plant lives in its own module with its own equations (numba-compiled NumPy),
importing nothing from ``clutchlab.physics`` components or effects, and differs from the
fit model in several component laws; each seed draws an "as-built" unit from physical
parameter ranges. Every modelling method is judged on these as well as on the stand.
"""

from .base import PlantEffect, PlantParameter, PlantSpec
from .effects import LIBRARY_EFFECTS
from .registry import PLANTS, get_plant, plant_names
from .run import PlantConfig, PlantRun, run_plant

__all__ = [
    "LIBRARY_EFFECTS",
    "PLANTS",
    "PlantConfig",
    "PlantEffect",
    "PlantParameter",
    "PlantRun",
    "PlantSpec",
    "get_plant",
    "plant_names",
    "run_plant",
]
