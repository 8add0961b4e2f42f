"""Base class of the circuit's components."""

from __future__ import annotations

from abc import ABC, abstractmethod

from ..assembly import Assembly
from ..parameters import Parameter

__all__ = ["Component", "param"]


def param(
    component: str,
    name: str,
    unit: str,
    default: float,
    lower: float,
    upper: float,
    description: str,
    transform: str = "log",
) -> Parameter:
    """Shorthand for a :class:`Parameter` owned by ``component`` (name ``<component>_<name>``)."""
    return Parameter(
        f"{component}_{name}",
        unit,
        default,
        lower,
        upper,
        description,
        transform=transform,
        component=component,
    )


class Component(ABC):
    """A physical part of the circuit.

    A component declares its parameters and states on an :class:`Assembly` and
    defines the signals it owns (forces, flows, state derivatives). Subclasses set
    ``name`` and ``PARAMETERS`` and implement :meth:`build`.
    """

    name: str = ""
    description: str = ""
    PARAMETERS: tuple[Parameter, ...] = ()

    def declare(self, asm: Assembly) -> None:
        """Declare the parameters, then build."""
        for p in self.PARAMETERS:
            asm.parameter(p)
        self.build(asm)

    @abstractmethod
    def build(self, asm: Assembly) -> None:
        """Declare states and define the component's signals on ``asm``."""
