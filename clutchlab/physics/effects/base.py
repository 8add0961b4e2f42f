"""Base class of the effect library: switchable model augmentations."""

from __future__ import annotations

from abc import ABC, abstractmethod

from ..assembly import Assembly
from ..parameters import Parameter

__all__ = ["Effect"]


class Effect(ABC):
    """A named physical effect the base model lacks, switchable on a model.

    Subclasses set:

    ``name``
        Registry name (``"sensor_lag"``).
    ``description``
        One line: the physics.
    ``signature``
        One line: what the residual of a model *without* the effect correlates
        with (spool direction, dI/dt, pressure level, temperature, …).
    ``PARAMETERS``
        The effect's own parameters (default = a typical strength when on).
    ``STRENGTH``
        Names of the parameters that switch the effect off exactly at zero: with
        all of them at 0 the model output equals the model without the effect.
    """

    name: str = ""
    description: str = ""
    signature: str = ""
    PARAMETERS: tuple[Parameter, ...] = ()
    STRENGTH: tuple[str, ...] = ()

    def declare(self, asm: Assembly) -> None:
        """Declare the parameters, then apply."""
        for p in self.PARAMETERS:
            asm.parameter(p)
        self.apply(asm)

    @abstractmethod
    def apply(self, asm: Assembly) -> None:
        """Wrap signals, add terms or states on ``asm``."""

    def __repr__(self) -> str:
        return f"<effect {self.name}>"
