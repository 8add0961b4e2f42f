"""Base class of the effect library: switchable model augmentations."""

from __future__ import annotations

from abc import ABC, abstractmethod

from ..assembly import Assembly, StateSpec
from ..parameters import Parameter

__all__ = ["Effect", "add_first_order_lag"]


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
    ``FIT``
        Parameters a fit frees when the effect is switched on (default ``STRENGTH``).
    ``REPLACES``
        Base-model parameters the effect retires (a law written in other
        parameters); they leave the model, so no fit frees them.
    ``HELD_SWITCH``
        The ``STRENGTH`` weights are a switch a fit holds on at 1 and never frees
        (``reg_pilot_lag``, ``latch_line_select``; default False).
    ``ALTERNATIVE_AFTER``
        A flexible law that discovery offers as an alternative to a candidate only
        when the model already holds these laws (``latch_pilot_lag`` after
        ``reg_pilot_lag``; default: always).
    ``WARM_ONLY``
        A flexible law meant to be added to a fit already made (``fit-physics --start``):
        no structure selection fits it from the datasheet start and discovery never
        offers it as an alternative (``latch_dither_band``; default False).
    """

    name: str = ""
    description: str = ""
    signature: str = ""
    PARAMETERS: tuple[Parameter, ...] = ()
    STRENGTH: tuple[str, ...] = ()
    #: Parameters a fit frees when the effect is on (default: the strength ones).
    FIT: tuple[str, ...] | None = None
    #: Base-model parameters the effect retires from the model.
    REPLACES: tuple[str, ...] = ()
    #: A switch whose STRENGTH weight a fit holds on at 1, never frees (flexible laws).
    HELD_SWITCH: bool = False
    #: Laws the model must hold before discovery offers this one as an alternative.
    ALTERNATIVE_AFTER: tuple[str, ...] = ()
    #: Added to a fit already made only (no structure selection, no discovery alternative).
    WARM_ONLY: bool = False

    @classmethod
    def fit_parameters(cls) -> tuple[str, ...]:
        """Names of the parameters a fitter frees for this effect."""
        return cls.FIT if cls.FIT is not None else cls.STRENGTH

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


def add_first_order_lag(
    asm: Assembly, signal: str, rate: str, state: StateSpec, kappa: str, tau: str
) -> None:
    """Lag ``signal`` (whose time derivative is signal ``rate``) by a blended first-order lag.

    ``y = x − κ e`` with ``de/dt = dx/dt − e/τ``: for κ = 1 exactly the lag
    ``τ dy/dt = x − y``, for κ = 0 exactly no effect (the state ``e`` then feeds
    nothing). Both ``signal`` and ``rate`` are wrapped, so lags compose.

    Parameters
    ----------
    asm : Assembly
        Where to declare.
    signal, rate : str
        Names of the lagged signal and of its time derivative.
    state : StateSpec
        The deficit state ``e`` (same unit as ``signal``).
    kappa, tau : str
        Names of the strength (-) and time-constant (s after conversion) parameters.
    """
    e = asm.state(state)
    tapped = f"{rate}_in:{state.name}"
    asm.tap(rate, tapped)
    asm.define(f"der:{state.name}", lambda a: a[tapped] - e / a.p(tau))
    asm.wrap(signal, lambda a, prev: prev - a.p(kappa) * e)
    asm.wrap(rate, lambda a, prev: prev - a.p(kappa) * (prev - e / a.p(tau)))
