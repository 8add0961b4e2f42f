"""The frozen circuit model: components + effects → CasADi functions."""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from functools import cached_property

import casadi as ca

from ..errors import ModelError
from .assembly import MODEL_INPUTS, Assembly, InputSpec, StateSpec
from .components import Component, default_components
from .effects.base import Effect
from .parameters import Parameter, ParameterSet

__all__ = ["OUTPUTS", "CircuitModel", "ModelFunctions", "OutputSpec"]


@dataclass(frozen=True)
class OutputSpec:
    """An output of the model (what a simulation returns per sample).

    Attributes
    ----------
    name : str
        Column name in results (``clutch_pressure_bar`` ...), ending in its unit.
    unit : str
        Unit of the output (``bar``, ``mm``, ``mA``, ``N``, ``-``).
    description : str
        What the output is.
    signal : str
        The model signal it reads (SI units).
    factor : float
        Factor from the signal's SI unit to ``unit`` (1e-5 for Pa → bar).
    """

    name: str
    unit: str
    description: str
    signal: str
    factor: float


#: Outputs of every model, in order. The first is what the sensor reads.
OUTPUTS: tuple[OutputSpec, ...] = (
    OutputSpec(
        "clutch_pressure_bar", "bar", "clutch pressure as the sensor reads it", "p_sensor", 1e-5
    ),
    OutputSpec(
        "clutch_pressure_true_bar", "bar", "clutch pressure at the clutch node", "out:p_c", 1e-5
    ),
    OutputSpec("pilot_pressure_bar", "bar", "VFS accumulator (pilot) pressure", "out:p_a", 1e-5),
    OutputSpec("vfs_pressure_bar", "bar", "VFS output chamber pressure", "out:p_vo", 1e-5),
    OutputSpec("feedback_pressure_bar", "bar", "regulator feedback pressure", "out:p_fb", 1e-5),
    OutputSpec("latch_state", "-", "latch valve opening (0 closed, 1 open)", "out:latch", 1.0),
    OutputSpec("regulator_position_mm", "mm", "regulator spool position", "out:x_r", 1e3),
    OutputSpec("coil_current_mA", "mA", "VFS coil current", "i_coil", 1e3),
    OutputSpec("magnetic_force_N", "N", "VFS magnetic force", "F_mag", 1.0),
)


@dataclass(frozen=True)
class ModelFunctions:
    """CasADi functions of one model for one drive mode (consumed by simulators, fitters, FMUs).

    ``rhs(x, u, p) -> dx`` (scaled states), ``out(x, u, p) -> y``; ``x``, ``u``,
    ``p`` in the order of ``states``, ``inputs``, ``parameters``.
    """

    drive: str
    states: tuple[StateSpec, ...]
    inputs: tuple[InputSpec, ...]
    parameters: tuple[Parameter, ...]
    outputs: tuple[OutputSpec, ...]
    rhs: ca.Function
    out: ca.Function
    x_sym: ca.SX
    u_sym: ca.SX
    p_sym: ca.SX
    dx_expr: ca.SX
    y_expr: ca.SX

    @property
    def nx(self) -> int:
        """Number of states."""
        return len(self.states)

    def state_index(self, name: str) -> int:
        """Position of state ``name``."""
        for k, s in enumerate(self.states):
            if s.name == name:
                return k
        raise ModelError(f"no state {name!r}; states: {[s.name for s in self.states]}")


@dataclass(frozen=True)
class CircuitModel:
    """Lumped-parameter model of the clutch control circuit, frozen once defined.

    Parameters
    ----------
    components : tuple of Component
        Physical parts; defaults to the base circuit.
    effects : tuple of Effect
        Switched-on augmentations from the effect library.
    name : str
        Model name used in reports and FMUs.

    Examples
    --------
    >>> from clutchlab.physics import CircuitModel
    >>> model = CircuitModel().with_effects("sensor_lag", "flow_force")
    >>> params = model.default_params().replace(reg_F_c=0.8)
    """

    components: tuple[Component, ...] = field(default_factory=default_components)
    effects: tuple[Effect, ...] = ()
    name: str = "clutch_circuit"

    def __post_init__(self) -> None:
        names = [e.name for e in self.effects]
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes:
            raise ModelError(f"effect(s) switched on twice: {', '.join(dupes)}")

    def __repr__(self) -> str:
        # the dataclass repr printed each component as <... object at 0x...>
        parts = ", ".join(c.name for c in self.components)
        return (
            f"CircuitModel(name={self.name!r}, effects={self.effect_names!r}, components=({parts}))"
        )

    # ---- structure ----------------------------------------------------------------
    @property
    def effect_names(self) -> tuple[str, ...]:
        """Names of the switched-on effects."""
        return tuple(e.name for e in self.effects)

    def with_effects(self, *effects: str | Effect) -> CircuitModel:
        """A new model with more effects switched on (names from the library or instances).

        A name string may list several effects separated by commas, as on the command
        line: ``with_effects("sensor_lag, transport_delay")``.

        Raises
        ------
        ModelError
            For an unknown effect name (the message lists the known ones) or an
            effect already on.
        """
        from .effects import effect_names, make_effect

        new = tuple(
            item
            for e in effects
            for item in (
                [e] if isinstance(e, Effect) else map(make_effect, effect_names(e, "with_effects"))
            )
        )
        return CircuitModel(self.components, self.effects + new, self.name)

    def without_effects(self, *names: str) -> CircuitModel:
        """A new model with the named effects switched off."""
        missing = sorted(set(names) - set(self.effect_names))
        if missing:
            raise ModelError(f"effect(s) not on: {', '.join(missing)}; on: {self.effect_names}")
        return CircuitModel(
            self.components, tuple(e for e in self.effects if e.name not in names), self.name
        )

    @cached_property
    def key(self) -> str:
        """Stable identifier of the model structure (components + effects)."""
        text = "|".join(type(c).__module__ + "." + type(c).__name__ for c in self.components)
        text += "||" + "|".join(type(e).__module__ + "." + type(e).__name__ for e in self.effects)
        return hashlib.sha1(text.encode()).hexdigest()[:12]

    # ---- parameters ---------------------------------------------------------------
    @cached_property
    def parameters(self) -> tuple[Parameter, ...]:
        """Every parameter (components, then effects), in model order."""
        return self.functions("measured").parameters

    def default_params(self) -> ParameterSet:
        """Datasheet defaults: the physics baseline (never fitted)."""
        return ParameterSet(self.parameters)

    def params(self, **values: float) -> ParameterSet:
        """Defaults with some values replaced (engineering units)."""
        return ParameterSet(self.parameters, values)

    def strength_parameters(self) -> dict[str, tuple[str, ...]]:
        """Per effect, the parameters that switch it off at zero."""
        return {e.name: e.STRENGTH for e in self.effects}

    # ---- symbolic functions ---------------------------------------------------------
    def functions(self, drive: str = "command") -> ModelFunctions:
        """Build (once, cached) the CasADi functions for ``drive`` ("command" or "measured")."""
        cache = self.__dict__.setdefault("_functions", {})
        if drive not in cache:
            cache[drive] = self._build(drive)
        return cache[drive]

    def _build(self, drive: str) -> ModelFunctions:
        asm = Assembly(drive)
        for comp in self.components:
            comp.declare(asm)
        for eff in self.effects:
            eff.declare(asm)
        for name in list(asm.states):
            asm.define(f"out:{name}", lambda a, n=name: a.x(n))
        x, u, p = asm.state_vector(), asm.input_vector(), asm.parameter_vector()
        dx = asm.derivative_vector()
        y = ca.vertcat(*(asm[o.signal] * o.factor for o in OUTPUTS))
        rhs = ca.Function("rhs", [x, u, p], [dx], ["x", "u", "p"], ["dx"])
        out = ca.Function("out", [x, u, p], [y], ["x", "u", "p"], ["y"])
        return ModelFunctions(
            drive=drive,
            states=tuple(asm.states.values()),
            inputs=MODEL_INPUTS,
            parameters=tuple(asm.parameters.values()),
            outputs=OUTPUTS,
            rhs=rhs,
            out=out,
            x_sym=x,
            u_sym=u,
            p_sym=p,
            dx_expr=dx,
            y_expr=y,
        )

    def custom_components(self) -> list[str]:
        """Names of the components that are not the base circuit's (another class, or
        another order): what a file that records only the effects cannot rebuild.

        Returns
        -------
        list of str
            ``"<position>: <class name>"`` of each differing component, and a note when the
            count differs; empty for the base circuit.
        """
        base = [type(c) for c in default_components()]
        mine = [type(c) for c in self.components]
        out = [
            f"{k}: {m.__name__}"
            for k, (m, b) in enumerate(zip(mine, base, strict=False))
            if m is not b
        ]
        if len(mine) != len(base):
            out.append(f"{len(mine)} components, the base circuit has {len(base)}")
        return out

    def describe(self) -> str:
        """Human-readable summary: components, effects, parameter count."""
        lines = [
            f"{self.name}: {len(self.components)} components, {len(self.parameters)} parameters"
        ]
        lines += [f"  component {c.name:8s} {c.description}" for c in self.components]
        lines += [f"  effect    {e.name:28s} {e.description}" for e in self.effects]
        return "\n".join(lines)
