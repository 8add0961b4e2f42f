"""The FMU program of a physics model: the simulator's sample step with the inputs mapped.

The FMU's step is exactly what :func:`clutchlab.physics.simulate` does per sample: the ROS2
sample step (:func:`~clutchlab.physics.integrator.sample_step_function`, ``substeps`` ROS2
steps per sample), inputs linear between the step's ends. The FMU keeps the dither phase
as a state and advances it with the trapezoidal integral of the dither frequency input, as
the simulator does on a trace. Initialization repeats the simulator's settling run.
"""

from __future__ import annotations

import math

import casadi as ca

from ...data import LINE_PRESSURE_BAR, SIGNALS
from ...errors import ModelError
from ..assembly import MODEL_INPUTS
from ..integrator import sample_step_function
from ..model import CircuitModel
from ..parameters import ParameterSet
from ..settings import MAX_SETTLE_S, SimulationSettings
from .errors import FmuError
from .program import FmuProgram, FmuVariable

__all__ = [
    "DRIVES",
    "FMU_INPUTS",
    "INTERNAL_STEP_S",
    "SUBSTEPS_RANGE",
    "SUPPLY_INPUTS",
    "check_export_options",
    "input_range",
    "physics_program",
]

DRIVES = ("command", "measured")

#: Longest internal step of a physics FMU (s): the simulator's sample step on 1 kHz data, at
#: which models are fitted and checked (``substeps`` ROS2 steps inside it, 0.25 ms at the
#: default 4). A longer communication step is split into internal steps of at most this;
#: the FMU refuses a ``max_step_s`` parameter above it (at 10 ms, ROS2 with 4 substeps
#: diverges on a 0→1100 mA ramp; at 1 s the clutch pressure reaches 240 bar).
INTERNAL_STEP_S = 1e-3

#: Allowed ROS2 substeps per internal step (as ``clutchlab fit-physics --substeps``).
SUBSTEPS_RANGE = (1, 16)

#: FMU inputs per drive: canonical signal name, unit, description, start value.
FMU_INPUTS: dict[str, tuple[tuple[str, str, str, float], ...]] = {
    "command": (
        ("current_cmd_mA", "mA", "nominal (commanded) VFS current, no dither", 0.0),
        ("dither_amp_mA", "mA", "dither amplitude (the FMU adds the dither)", 0.0),
        ("dither_freq_Hz", "Hz", "dither frequency; the FMU integrates it to the phase", 50.0),
    ),
    "measured": (
        ("current_mA", "mA", "measured VFS coil current, dither included", 0.0),
        ("dither_amp_mA", "mA", "dither amplitude (dither-dependent effects)", 0.0),
        ("dither_freq_Hz", "Hz", "dither frequency", 50.0),
    ),
}
_COMMON_INPUTS = (
    ("line_pressure_bar", "bar", "line (supply) pressure, gauge", LINE_PRESSURE_BAR),
    ("prime_pressure_bar", "bar", "prime / exhaust backfill pressure, gauge", 0.5),
    ("oil_temp_C", "°C", "oil temperature", 40.0),
)
_WAVES = ("sine", "triangle", "square")

#: Inputs whose highest value so far bounds the FMU's pressure outputs (bar): the line and
#: the prime pressure (see :attr:`~clutchlab.physics.fmu.program.FmuProgram.supply_inputs`).
SUPPLY_INPUTS = ("line_pressure_bar", "prime_pressure_bar")


def input_range(name: str) -> tuple[float, float]:
    """Declared ``min`` / ``max`` of an FMU input, which the FMU enforces.

    Parameters
    ----------
    name : str
        Canonical signal name of the input (``current_cmd_mA`` …).

    Returns
    -------
    (float, float)
        The plausible range of the signal in its unit (:data:`clutchlab.data.SIGNALS`:
        −300 … 2000 mA for a current, 0 … 500 mA / Hz for the dither, −1 … 60 bar for a
        pressure, −40 … 180 °C): a value outside it is a signal in another unit or one the
        model was never made for, refused by the FMU with its name.
    """
    spec = SIGNALS[name]
    return spec.plausible_min, spec.plausible_max


_U = {s.name: k for k, s in enumerate(MODEL_INPUTS)}


def _model_inputs(drive: str, v: ca.SX, dv: ca.SX, phase: ca.SX, waves: ca.SX) -> ca.SX:
    """The model input vector (:data:`MODEL_INPUTS` order) from FMU inputs ``v``."""
    u = [ca.SX(0)] * len(MODEL_INPUTS)
    if drive == "command":
        u[_U["current_nom_mA"]] = v[0]
    else:
        u[_U["current_meas_mA"]] = v[0]
        u[_U["current_meas_rate_mA_s"]] = dv[0]  # slope over the step, as on a trace
    u[_U["dither_amp_mA"]] = v[1]
    u[_U["dither_freq_Hz"]] = v[2]
    u[_U["dither_phase"]] = phase
    for k, w in enumerate(_WAVES):
        u[_U[f"wave_{w}"]] = waves[k]
    u[_U["line_pressure_bar"]] = v[3]
    u[_U["prime_pressure_bar"]] = v[4]
    u[_U["oil_temp_C"]] = v[5]
    return ca.vertcat(*u)


def check_export_options(
    substeps: int | None = None, step_s: float = 1e-3, stop_time_s: float = 23.0
) -> None:
    """Refuse export options that would build a wrong FMU, before any work is done.

    Parameters
    ----------
    substeps : int, optional
        ROS2 steps per internal step: an integer in :data:`SUBSTEPS_RANGE` (1 … 16), or
        None (the default).
    step_s : float
        Default experiment communication step (s): finite and > 0.
    stop_time_s : float
        Default experiment stop time (s): finite and > ``step_s``.

    Raises
    ------
    FmuError
        Every problem found, one per line.
    """
    lo, hi = SUBSTEPS_RANGE
    problems = []
    if substeps is not None and (
        isinstance(substeps, bool) or int(substeps) != substeps or not lo <= substeps <= hi
    ):
        problems.append(
            f"substeps must be {lo}..{hi} (ROS2 steps per internal step of "
            f"{INTERNAL_STEP_S * 1e3:g} ms), not {substeps!r}"
        )
    if not (isinstance(step_s, int | float) and math.isfinite(step_s) and step_s > 0):
        problems.append(f"step must be a positive number of seconds, not {step_s!r}")
    elif not (
        isinstance(stop_time_s, int | float) and math.isfinite(stop_time_s) and stop_time_s > step_s
    ):
        problems.append(
            f"stop time must be a number of seconds above the step ({step_s:g} s), "
            f"not {stop_time_s!r}"
        )
    if problems:
        raise FmuError("invalid FMU export options", problems)


def physics_program(
    model: CircuitModel,
    params: ParameterSet,
    drive: str = "command",
    substeps: int | None = None,
    settings: SimulationSettings | None = None,
    name: str | None = None,
    step_s: float = 1e-3,
    stop_time_s: float = 23.0,
    origin: dict[str, str] | None = None,
) -> FmuProgram:
    """The FMU program of ``model`` with parameter values ``params``.

    Parameters
    ----------
    model : CircuitModel
        Frozen model structure (base circuit + effects).
    params : ParameterSet
        Parameter values (engineering units), e.g. a fit result's; they become the FMU's
        parameter start values.
    drive : {"command", "measured"}
        ``command``: inputs are the nominal current (mA), dither amplitude (mA) and
        frequency (Hz); the FMU builds the dithered command and runs the current loop — the
        co-simulation case (a TCU model commands the current). ``measured``: the input is
        the measured coil current (mA, dither included) — replaying stand logs; its slope
        over a step comes from the input derivative (set it, or the current is held).
    substeps : int, optional
        ROS2 steps per internal step of :data:`INTERNAL_STEP_S` (1 ms), 1 … 16; default
        ``settings.substeps`` (4).
    settings : SimulationSettings, optional
        Settling time and waveform defaults (the simulator's defaults otherwise).
    name : str, optional
        Model identifier; default ``<model.name>_<drive>``.
    step_s : float
        Communication step of the default experiment (s), > 0. It does not change what
        the FMU computes: whatever step the master takes, the FMU integrates in internal
        steps of at most ``max_step_s`` (parameter; start and upper bound
        :data:`INTERNAL_STEP_S`).
    stop_time_s : float
        Default experiment stop time (s), > ``step_s``.
    origin : dict, optional
        Where the parameter values come from
        (:func:`~clutchlab.physics.fmu.export.source_origin`): its ``"summary"`` goes into
        the description, its other keys into the vendor annotation. Default: values as
        given.

    Returns
    -------
    FmuProgram

    Raises
    ------
    FmuError
        ``substeps`` outside 1 … 16, or a step or stop time that is not a positive number
        (checked before anything is built).
    ModelError
        An unknown ``drive``.
    """
    if drive not in DRIVES:
        raise ModelError(f"drive must be one of {DRIVES}, not {drive!r}")
    check_export_options(substeps, step_s, stop_time_s)
    settings = settings or SimulationSettings()
    substeps = settings.substeps if substeps is None else int(substeps)
    fns = model.functions(drive)
    nx_m, npar_m = fns.nx, len(fns.parameters)
    spec = FMU_INPUTS[drive] + _COMMON_INPUTS
    inputs = tuple(FmuVariable(n, u, d, s, *input_range(n)) for n, u, d, s in spec)
    outputs = tuple(FmuVariable(o.name, o.unit, o.description) for o in fns.outputs)
    model_pars = tuple(
        FmuVariable(
            p.name,
            p.unit,
            f"{p.description} (model parameter, component {p.component})",
            float(params[p.name]),
            *((p.lower, p.upper) if p.lower <= params[p.name] <= p.upper else (None, None)),
        )
        for p in fns.parameters
    )
    wave_default = settings.dither_waveform
    extra = (
        *(
            FmuVariable(
                f"dither_wave_{w}",
                "-",
                f"weight of the {w} dither waveform (sum 1 for a pure waveform)",
                1.0 if w == wave_default else 0.0,
            )
            for w in _WAVES
        ),
        FmuVariable(
            "settle_s",
            "s",
            "settling run at the initial inputs before t = 0",
            settings.settle_s,
            0.0,
            MAX_SETTLE_S,
        ),
        FmuVariable("settle_step_s", "s", "step of the settling run", INTERNAL_STEP_S),
        FmuVariable(
            "max_step_s",
            "s",
            f"longest internal step ({substeps} ROS2 substeps each); longer communication "
            f"steps are split; at most {INTERNAL_STEP_S:g} s (refused above)",
            INTERNAL_STEP_S,
            None,
            INTERNAL_STEP_S,
        ),
    )
    parameters = model_pars + extra
    nv, npar = len(inputs), len(parameters)
    sample = sample_step_function(fns, substeps)

    x = ca.SX.sym("x", 1 + nx_m)  # [dither phase (cycles); model states]
    v, dv, h, p = ca.SX.sym("v", nv), ca.SX.sym("dv", nv), ca.SX.sym("h"), ca.SX.sym("p", npar)
    pm, waves = p[:npar_m], p[npar_m : npar_m + 3]
    phase0, xm = x[0], x[1:]

    # Communication step: inputs linear over [t, t + h]; trapezoidal phase (as input_matrix).
    v1 = v + h * dv
    phase1 = phase0 + 0.5 * (v[2] + v1[2]) * h
    u0 = _model_inputs(drive, v, dv, phase0, waves)
    u1 = _model_inputs(drive, v1, dv, phase1, waves)
    xm1, y1 = sample(xm, u0, u1, h, pm)
    step = ca.Function(
        "step",
        [x, v, dv, h, p],
        [ca.vertcat(phase1, xm1), y1],
        ["x", "v", "dv", "h", "p"],
        ["x1", "y1"],
    )

    # Settling step: inputs frozen at their initial values, the dither phase running.
    phase_s = phase0 + v[2] * h
    xs1, _ = sample(xm, u0, _model_inputs(drive, v, dv, phase_s, waves), h, pm)
    settle = ca.Function("settle", [x, v, dv, h, p], [ca.vertcat(phase_s, xs1)])

    # Start: declared initial values, the coil current at its command (simulate.initial_state).
    t_pre = ca.SX.sym("t_pre")
    x0 = [ca.SX(s.initial) for s in fns.states]
    if drive == "command":
        x0[fns.state_index("i")] = ca.fmax(v[0], 0.0)
    start = ca.Function("start", [v, dv, p, t_pre], [ca.vertcat(-v[2] * t_pre, *x0)])

    output = ca.Function("output", [x, v, p], [fns.out(xm, u0, pm)])
    ident = name or f"{model.name}_{drive}"
    effects = ", ".join(model.effect_names) or "none"
    origin = dict(origin or {"source": "given", "summary": "as given"})
    summary = origin.pop("summary", origin.get("source", "given"))
    return FmuProgram(
        name=ident,
        description=(
            f"clutchlab physics model of the clutch control circuit ({drive} drive; "
            f"effects: {effects}); ROS2, {substeps} substeps per internal step of at most "
            f"{INTERNAL_STEP_S * 1e3:g} ms. Parameter values: {summary}"
        ),
        kind="physics",
        inputs=inputs,
        outputs=outputs,
        parameters=parameters,
        nx=1 + nx_m,
        start=start,
        settle=settle,
        step=step,
        output=output,
        step_s=step_s,
        stop_time_s=stop_time_s,
        max_step_s=INTERNAL_STEP_S,
        pressure_outputs=tuple(o.name for o in outputs if o.unit == "bar"),
        supply_inputs=SUPPLY_INPUTS,
        annotations={
            "kind": "physics",
            "drive": drive,
            "substeps": str(substeps),
            "effects": ",".join(model.effect_names),
            "model_key": model.key,
            "states": ",".join(["dither_phase", *(s.name for s in fns.states)]),
            **origin,
        },
    )
