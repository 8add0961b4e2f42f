"""What an FMU computes, as CasADi functions plus the variables' metadata.

An :class:`FmuProgram` is everything the exporter needs and nothing model-specific: the
generic C wrapper (:mod:`.csource`) calls its functions and knows only their sizes. A
physics model, a standalone ML model and a hybrid each build one; the exporter turns any
of them into the same kind of FMU.

The functions, with ``v`` the FMU inputs (order of :attr:`FmuProgram.inputs`), ``dv`` their
time derivatives (1/s, zero unless the importer sets them with
``fmi2SetRealInputDerivatives``), ``h`` the step (s), ``p`` the Real parameters (order of
:attr:`FmuProgram.parameters`) and ``x`` the internal state:

``start(v, dv, p, t_pre) -> x``
    The state before initialization; ``t_pre`` (s) is the duration of the settling run
    that follows (a dither phase starts at ``−f·t_pre`` so that it reaches 0 at t = 0).
``settle(x, v, dv, h, p) -> x``
    One settling step at frozen inputs (optional).
``step(x, v, dv, h, p) -> (x, y)``
    One communication step: inputs ``v`` at its start, ``v + h·dv`` at its end (linear in
    between); ``y`` the outputs at its end.
``output(x, v, p) -> y``
    Outputs at a state (after initialization).

Every function takes the program's :attr:`FmuProgram.constants` as extra trailing inputs
(none for a physics model): large arrays (GP training points, ``K⁻¹``, support vectors)
that would bloat the C source are stored in ``resources/`` of the FMU, loaded once by
``fmi2Instantiate`` and passed by pointer (no copy per step).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from ...errors import ModelError

__all__ = ["RESERVED_PARAMETERS", "FmuProgram", "FmuVariable"]

#: Parameters the C wrapper itself reads (by name), when the program declares them.
RESERVED_PARAMETERS: tuple[str, ...] = ("settle_s", "settle_step_s", "max_step_s")

_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


@dataclass(frozen=True)
class FmuVariable:
    """A Real variable of the FMU.

    Attributes
    ----------
    name : str
        Variable name (flat naming convention; an identifier).
    unit : str
        clutchlab unit string (``"mA"``, ``"bar"``, ``"°C"`` …; ``"-"`` dimensionless).
    description : str
        Meaning, written into ``modelDescription.xml``.
    start : float
        Start value in ``unit`` (inputs and parameters; ignored for outputs).
    min, max : float or None
        Declared range in ``unit`` (parameters: the physical bounds).
    """

    name: str
    unit: str
    description: str
    start: float = 0.0
    min: float | None = None
    max: float | None = None


@dataclass(frozen=True)
class FmuProgram:
    """An exportable model: CasADi functions (see the module docstring) and variables.

    Attributes
    ----------
    name : str
        Model identifier (an identifier: names the binary and the C symbols' prefix).
    description : str
        One-line description of the model.
    kind : str
        ``"physics"``, ``"ml"`` or ``"hybrid"`` (recorded in the vendor annotation).
    inputs, outputs, parameters : tuple of FmuVariable
        The FMU's inputs, outputs and Real parameters, in the order of ``v``, ``y``, ``p``.
    nx : int
        Length of the internal state.
    start, settle, step, output : casadi.Function
        See the module docstring; ``settle`` may be None.
    step_s : float
        Communication step of the default experiment (s): its ``stepSize`` only; it does
        not change what the FMU computes.
    stop_time_s : float
        Default experiment stop time (s).
    max_step_s : float
        Longest internal step the model is accurate at (s). ``fmi2DoStep`` splits a longer
        communication step into equal internal steps of at most this (of at most the
        ``max_step_s`` parameter, when the program declares one: that parameter must be
        ``> 0`` and ``≤`` this, else ``fmi2ExitInitializationMode`` refuses it).
    annotations : dict
        Extra ``key → value`` strings written into the clutchlab vendor annotation.
    constants : tuple of ndarray
        Arrays passed as extra trailing inputs of every function (each as a dense matrix,
        column-major), stored in the FMU's resources.
    pressure_outputs : tuple of str
        Outputs (bar) the FMU checks after initialization and every step against the range
        the circuit can reach: ``[PHYSICAL_PRESSURE_MIN_BAR,
        PHYSICAL_PRESSURE_LINE_FACTOR × max(highest supply pressure so far, 1 bar)]``
        (as :meth:`~clutchlab.physics.SimulationResult.check_pressures`); a value outside it
        (a fixed-step solution that stays finite but is wrong by thousands of bar) is an
        error naming the output. Empty: no check.
    supply_inputs : tuple of str
        Inputs (bar) whose highest value so far is the supply pressure of that check (line
        and prime pressure); required when ``pressure_outputs`` is not empty.

    Inputs with a declared ``min`` / ``max`` are checked against it by ``fmi2DoStep`` and
    ``fmi2ExitInitializationMode`` (an input outside it, e.g. a current given in A, is an
    error naming it); every input and parameter must be finite.
    """

    name: str
    description: str
    kind: str
    inputs: tuple[FmuVariable, ...]
    outputs: tuple[FmuVariable, ...]
    parameters: tuple[FmuVariable, ...]
    nx: int
    start: ca.Function
    settle: ca.Function | None
    step: ca.Function
    output: ca.Function
    step_s: float = 1e-3
    stop_time_s: float = 10.0
    max_step_s: float = 1e-3
    annotations: dict[str, str] = field(default_factory=dict)
    constants: tuple[np.ndarray, ...] = ()
    pressure_outputs: tuple[str, ...] = ()
    supply_inputs: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        problems = []
        if not _NAME.match(self.name):
            problems.append(f"model name {self.name!r} is not a C identifier")
        names = [v.name for v in (*self.inputs, *self.outputs, *self.parameters)]
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes:
            problems.append(f"variable name(s) used twice: {', '.join(dupes)}")
        problems += [
            f"variable name {n!r} is not an identifier" for n in names if not _NAME.match(n)
        ]
        nv, ny, npar = len(self.inputs), len(self.outputs), len(self.parameters)
        nc = [int(np.size(c)) for c in self.constants]
        expect = {
            "start": ([nv, nv, npar, 1, *nc], [self.nx]),
            "step": ([self.nx, nv, nv, 1, npar, *nc], [self.nx, ny]),
            "output": ([self.nx, nv, npar, *nc], [ny]),
        }
        if self.settle is not None:
            expect["settle"] = ([self.nx, nv, nv, 1, npar, *nc], [self.nx])
        for key, (ins, outs) in expect.items():
            fn: ca.Function = getattr(self, key)
            got_in = [fn.size1_in(k) * fn.size2_in(k) for k in range(fn.n_in())]
            got_out = [fn.size1_out(k) * fn.size2_out(k) for k in range(fn.n_out())]
            if got_in != ins or got_out != outs:
                problems.append(
                    f"function {key}: inputs {got_in} / outputs {got_out}, expected {ins} / {outs}"
                )
        if not 0 < self.step_s < self.stop_time_s:
            problems.append(f"step_s {self.step_s} must be in (0, stop_time_s)")
        if not (np.isfinite(self.max_step_s) and self.max_step_s > 0):
            problems.append(f"max_step_s {self.max_step_s} must be finite and > 0")
        k = self.parameter_index("max_step_s")
        if k >= 0 and not 0 < self.parameters[k].start <= self.max_step_s:
            problems.append(
                f"parameter max_step_s starts at {self.parameters[k].start}, outside "
                f"(0, {self.max_step_s}] (max_step_s)"
            )
        outputs = {v.name: v.unit for v in self.outputs}
        inputs = {v.name: v.unit for v in self.inputs}
        problems += [
            f"pressure output {n!r} is not an output in bar"
            for n in self.pressure_outputs
            if outputs.get(n) != "bar"
        ]
        problems += [
            f"supply input {n!r} is not an input in bar"
            for n in self.supply_inputs
            if inputs.get(n) != "bar"
        ]
        if self.pressure_outputs and not self.supply_inputs:
            problems.append("pressure_outputs are checked against supply_inputs: none given")
        problems += [
            f"input {v.name!r}: min {v.min} above max {v.max}"
            for v in self.inputs
            if v.min is not None and v.max is not None and v.min > v.max
        ]
        if problems:
            raise ModelError("invalid FMU program:\n  - " + "\n  - ".join(problems))

    def parameter_index(self, name: str) -> int:
        """Position of parameter ``name`` in ``p``, or −1 when the program has none."""
        for k, v in enumerate(self.parameters):
            if v.name == name:
                return k
        return -1

    def constants_blob(self) -> bytes:
        """The constants, column-major float64 little-endian, one after the other."""
        return b"".join(
            np.asarray(c, dtype="<f8").flatten(order="F").tobytes() for c in self.constants
        )

    def functions(self) -> dict[str, ca.Function]:
        """The functions to generate C for, named ``<name>_<role>`` (C symbols)."""
        out = {"start": self.start, "step": self.step, "output": self.output}
        if self.settle is not None:
            out["settle"] = self.settle
        return {role: _renamed(fn, f"{self.name}_{role}") for role, fn in out.items()}


def _renamed(fn: ca.Function, name: str) -> ca.Function:
    """``fn`` under another name, its expression graph inlined (no wrapper call)."""
    args = fn.sx_in() if fn.is_a("SXFunction") else fn.mx_in()
    return ca.Function(name, args, fn.call(args), fn.name_in(), fn.name_out())
