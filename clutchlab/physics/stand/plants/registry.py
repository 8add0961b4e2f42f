"""The zoo's plants by name."""

from __future__ import annotations

from ....errors import ModelError
from . import preisach_accumulator, quadratic_play, saturating_lugre, stribeck_supply
from .base import PlantSpec

__all__ = ["PLANTS", "get_plant", "plant_names"]

#: Every plant of the zoo, by name.
PLANTS: dict[str, PlantSpec] = {
    m.SPEC.name: m.SPEC
    for m in (saturating_lugre, quadratic_play, stribeck_supply, preisach_accumulator)
}


def plant_names() -> list[str]:
    """Names of the zoo's plants."""
    return list(PLANTS)


def get_plant(name: str) -> PlantSpec:
    """The plant called ``name``; :class:`ModelError` listing the known ones otherwise."""
    try:
        return PLANTS[name]
    except KeyError:
        raise ModelError(
            f"unknown plant {name!r}; known: stand (the default), {', '.join(PLANTS)}"
        ) from None
