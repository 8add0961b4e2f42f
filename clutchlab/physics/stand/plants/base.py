"""What a plant of the zoo is: its component laws, as-built parameter ranges, effects.

A plant is a reference clutch circuit written independently of clutchlab's fit model:
its own equations in its own module, compiled with numba, importing nothing from
``clutchlab.physics`` components or effects (``tests/test_plants.py`` reads the
imports). It declares

- the component laws in which it differs from the fit model (for the reader);
- its parameters as physical ranges: each seed draws one "as-built" unit;
- the library effects it can carry, each as extra parameters of its own equations,
  and the reasons it refuses the others.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ....errors import ModelError

__all__ = ["PlantEffect", "PlantParameter", "PlantSpec"]


@dataclass(frozen=True)
class PlantParameter:
    """One as-built parameter: drawn uniformly in ``[low, high]`` per seed.

    Attributes
    ----------
    name : str
    low, high : float
        Range of the as-built spread (``unit``).
    unit : str
    doc : str
    """

    name: str
    low: float
    high: float
    unit: str
    doc: str


@dataclass(frozen=True)
class PlantEffect:
    """A library effect as this plant carries it: parameters of its own equations.

    Attributes
    ----------
    how : str
        What the effect does in this plant's equations.
    values : dict of str to (low, high)
        Parameters the effect sets (drawn per seed in the range). Each is also in the
        plant's ``parameters`` with the range (0, 0): zero, the effect absent, otherwise.
    """

    how: str
    values: dict[str, tuple[float, float]]


@dataclass(frozen=True)
class PlantSpec:
    """A plant of the zoo.

    Attributes
    ----------
    name : str
        Name used by ``clutchlab stand --plant``.
    summary : str
        One line for ``--list-plants``.
    laws : dict of str to str
        Component → the law this plant uses where it differs from the fit model.
    parameters : tuple of PlantParameter
        As-built parameters in the order of the simulation kernel's parameter vector.
    effects : dict of str to PlantEffect
        Library effects this plant can carry.
    refused : dict of str to str
        Library effects it cannot carry, with the reason.
    simulate : callable
        ``simulate(values, drive, substeps) -> (current_mA, pressure_bar)``: the true coil
        current and the pressure at the transducer's output at the drive's sample times.
    """

    name: str
    summary: str
    laws: dict[str, str]
    parameters: tuple[PlantParameter, ...]
    effects: dict[str, PlantEffect]
    refused: dict[str, str]
    simulate: Callable = field(repr=False)

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Names of the kernel's parameter vector, in order."""
        return tuple(p.name for p in self.parameters)

    def check_effects(self, effects) -> None:
        """Raise :class:`ModelError` for an effect this plant cannot carry (with the reason)."""
        for name in effects:
            if name in self.effects:
                continue
            if name in self.refused:
                raise ModelError(f"plant {self.name!r} cannot carry {name!r}: {self.refused[name]}")
            raise ModelError(
                f"unknown effect {name!r} for plant {self.name!r}; it carries: "
                f"{', '.join(sorted(self.effects))}"
            )

    def draw(self, rng: np.random.Generator, effects=()) -> dict[str, float]:
        """One as-built unit: every parameter drawn in its range, effects switched on.

        Effect parameters not switched on are zero.
        """
        self.check_effects(effects)
        values = {p.name: float(rng.uniform(p.low, p.high)) for p in self.parameters}
        for name in effects:
            for k, (lo, hi) in self.effects[name].values.items():
                values[k] = float(rng.uniform(lo, hi))
        return values

    def vector(self, values: dict[str, float]) -> np.ndarray:
        """The kernel's parameter vector from named values."""
        missing = [n for n in self.parameter_names if n not in values]
        if missing:
            raise ModelError(f"plant {self.name!r}: missing parameter(s) {', '.join(missing)}")
        return np.array([values[n] for n in self.parameter_names], dtype=float)
