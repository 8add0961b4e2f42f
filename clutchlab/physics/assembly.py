"""Symbolic assembly of the circuit: a lazy graph of named signals.

Components and effects never write the state equations directly. They *define*
named signals (``"F_reg_friction"``, ``"Q_clutch_in"``, ``"der:p_c"`` …), *wrap*
signals defined by others (an effect replaces the friction law by a Stribeck law
by wrapping ``"F_reg_friction"``) and *add terms* to sums (an effect adds a flow
force to ``"F_reg"``). Signals are evaluated lazily, once, when the model is
frozen, so the order in which components and effects were declared does not
matter. All signals are in SI units.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import casadi as ca

from ..errors import ModelError
from .parameters import Parameter
from .units import SI_FACTOR

__all__ = ["Assembly", "InputSpec", "StateSpec"]

SignalFn = Callable[["Assembly"], ca.SX]
WrapFn = Callable[["Assembly", ca.SX], ca.SX]


@dataclass(frozen=True)
class StateSpec:
    """A continuous state of the model.

    Attributes
    ----------
    name : str
        State name (``p_c``, ``x_r`` …).
    unit : str
        Engineering unit the integrator works in (``bar``, ``mm`` …): states are
        scaled so that their typical magnitudes are of order one.
    initial : float
        Initial guess in ``unit`` before the settling run.
    description : str
        Meaning.
    owner : str
        Component or effect that declared it.
    """

    name: str
    unit: str
    initial: float
    description: str
    owner: str = ""

    @property
    def si_factor(self) -> float:
        """Factor from ``unit`` to SI."""
        return SI_FACTOR[self.unit]


@dataclass(frozen=True)
class InputSpec:
    """A time-varying input of the model (linearly interpolated between samples)."""

    name: str
    unit: str
    description: str


#: Inputs of every model, in this order. ``dither_phase`` is the integral of the
#: dither frequency (cycles); the ``wave_*`` inputs weight the dither waveform.
MODEL_INPUTS: tuple[InputSpec, ...] = (
    InputSpec("current_nom_mA", "mA", "nominal (commanded) solenoid current, no dither"),
    InputSpec("dither_amp_mA", "mA", "dither amplitude"),
    InputSpec("dither_freq_Hz", "Hz", "dither frequency"),
    InputSpec("dither_phase", "-", "dither phase in cycles, integral of the frequency"),
    InputSpec("wave_sine", "-", "weight of the sine dither waveform"),
    InputSpec("wave_triangle", "-", "weight of the triangle dither waveform"),
    InputSpec("wave_square", "-", "weight of the square dither waveform"),
    InputSpec("current_meas_mA", "mA", "measured solenoid current, dither included"),
    InputSpec("current_meas_rate_mA_s", "mA/s", "slope of the measured current over the sample"),
    InputSpec("line_pressure_bar", "bar", "line (supply) pressure, gauge"),
    InputSpec("prime_pressure_bar", "bar", "prime / exhaust backfill pressure, gauge"),
    InputSpec("oil_temp_C", "°C", "oil temperature"),
)


class Assembly:
    """Collects parameters, states and signal definitions; evaluates them to SX.

    Parameters
    ----------
    drive : {"command", "measured"}
        ``command``: the coil current follows the dithered command through the
        current loop (a state). ``measured``: the coil current is the measured
        current input (no current state).
    """

    def __init__(self, drive: str) -> None:
        if drive not in ("command", "measured"):
            raise ModelError(f"drive must be 'command' or 'measured', not {drive!r}")
        self.drive = drive
        self.parameters: dict[str, Parameter] = {}
        self.states: dict[str, StateSpec] = {}
        self._p_sym: dict[str, ca.SX] = {}
        self._x_sym: dict[str, ca.SX] = {}
        self.u = {spec.name: ca.SX.sym(spec.name) for spec in MODEL_INPUTS}
        self._defs: dict[str, SignalFn] = {}
        self._wraps: dict[str, list[WrapFn]] = {}
        self._terms: dict[str, list[SignalFn]] = {}
        self._units: dict[str, str] = {}
        self._cache: dict[str, ca.SX] = {}
        self._evaluating: list[str] = []

    # ---- declarations -------------------------------------------------------------
    def parameter(self, spec: Parameter) -> ca.SX:
        """Declare a parameter; return its value **in SI** as a symbolic expression."""
        if spec.name in self.parameters:
            if self.parameters[spec.name] != spec:
                raise ModelError(f"parameter {spec.name!r} declared twice, differently")
        else:
            self.parameters[spec.name] = spec
            self._p_sym[spec.name] = ca.SX.sym(spec.name)
        return self._p_sym[spec.name] * spec.si_factor

    def p(self, name: str) -> ca.SX:
        """SI value of a declared parameter."""
        try:
            return self._p_sym[name] * self.parameters[name].si_factor
        except KeyError:
            raise ModelError(f"parameter {name!r} is not declared") from None

    def state(self, spec: StateSpec) -> ca.SX:
        """Declare a state; return its value **in SI**. Its derivative is signal ``der:<name>``."""
        if spec.name in self.states:
            raise ModelError(f"state {spec.name!r} declared twice")
        self.states[spec.name] = spec
        self._x_sym[spec.name] = ca.SX.sym(spec.name)
        return self._x_sym[spec.name] * spec.si_factor

    def x(self, name: str) -> ca.SX:
        """SI value of a declared state."""
        try:
            return self._x_sym[name] * self.states[name].si_factor
        except KeyError:
            raise ModelError(f"state {name!r} is not declared") from None

    def define(self, name: str, fn: SignalFn, unit: str = "") -> None:
        """Define signal ``name`` as ``fn(assembly)`` (SI)."""
        if name in self._defs:
            raise ModelError(f"signal {name!r} defined twice")
        self._defs[name] = fn
        self._units[name] = unit

    def wrap(self, name: str, fn: WrapFn) -> None:
        """Replace signal ``name`` by ``fn(assembly, previous_expression)``."""
        self._wraps.setdefault(name, []).append(fn)

    def redefine(self, name: str, fn: SignalFn) -> None:
        """Replace the definition of signal ``name`` (a flexible law in place of a component's).

        Wraps and terms added to ``name`` still apply on top of the new definition.

        Raises
        ------
        ModelError
            If ``name`` has no definition to replace.
        """
        if name not in self._defs:
            raise ModelError(f"signal {name!r} is not defined; nothing to redefine")
        self._defs[name] = fn

    def retire_parameter(self, name: str) -> None:
        """Remove a declared parameter that a replacing law no longer uses.

        A definition that still reads it fails loudly when evaluated ("not declared").

        Raises
        ------
        ModelError
            If ``name`` is not declared.
        """
        if name not in self.parameters:
            raise ModelError(f"parameter {name!r} is not declared; nothing to retire")
        del self.parameters[name]
        del self._p_sym[name]

    def tap(self, name: str, new_name: str) -> None:
        """Define ``new_name`` as signal ``name`` as it is *now* in its wrap chain.

        An effect that filters a signal (a lag on ``dp_sensor``) needs the signal
        before its own wrap; tapping it first avoids a cycle.
        """
        self._wraps.setdefault(name, []).append(("tap", new_name))

        def tapped(a, name=name, new_name=new_name):
            a[name]
            return a._cache[new_name]

        self.define(new_name, tapped)

    def add_term(self, name: str, fn: SignalFn) -> None:
        """Add ``fn(assembly)`` to the sum signal ``name`` (a sum is zero without terms)."""
        self._terms.setdefault(name, []).append(fn)

    # ---- evaluation ---------------------------------------------------------------
    def has(self, name: str) -> bool:
        """Whether signal ``name`` has a definition or terms."""
        return name in self._defs or name in self._terms

    def __getitem__(self, name: str) -> ca.SX:
        if name in self._cache:
            return self._cache[name]
        if name in self._evaluating:
            cycle = " -> ".join([*self._evaluating, name])
            raise ModelError(f"signal cycle: {cycle}")
        if not self.has(name):
            raise ModelError(f"signal {name!r} is not defined")
        self._evaluating.append(name)
        try:
            expr = self._defs[name](self) if name in self._defs else ca.SX(0)
            for term in self._terms.get(name, []):
                expr = expr + term(self)
            for fn in self._wraps.get(name, []):
                if isinstance(fn, tuple):  # a tap: snapshot of the chain so far
                    self._cache[fn[1]] = expr
                else:
                    expr = fn(self, expr)
        finally:
            self._evaluating.pop()
        self._cache[name] = expr
        return expr

    # ---- vectors ------------------------------------------------------------------
    def parameter_vector(self) -> ca.SX:
        """Parameter symbols (engineering units) in declaration order."""
        return ca.vertcat(*self._p_sym.values())

    def state_vector(self) -> ca.SX:
        """State symbols (scaled, engineering units) in declaration order."""
        return ca.vertcat(*self._x_sym.values())

    def input_vector(self) -> ca.SX:
        """Input symbols in :data:`MODEL_INPUTS` order."""
        return ca.vertcat(*(self.u[s.name] for s in MODEL_INPUTS))

    def derivative_vector(self) -> ca.SX:
        """Scaled state derivatives ``d(state in unit)/dt`` in state order."""
        return ca.vertcat(*(self[f"der:{n}"] / s.si_factor for n, s in self.states.items()))
