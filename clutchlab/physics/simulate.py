"""Simulate a model on a trace's time grid."""

from __future__ import annotations

import time
import warnings

import numpy as np

from ..data import Dataset, Trace
from ..errors import ModelError, SimulationError, SimulationWarning
from .assembly import MODEL_INPUTS
from .dense_call import DenseCall
from .inputs import choose_drive, input_matrix, interval_inputs, split_intervals
from .integrator import chunk_function
from .model import CircuitModel, ModelFunctions
from .parameters import ParameterSet
from .result import SimulationResult
from .settings import COARSE_INTERVAL_S, MAX_STEP_S, SimulationSettings, steps_per_interval

__all__ = ["model_params", "simulate", "simulate_inputs"]


def simulate(
    model: CircuitModel,
    params: ParameterSet | None,
    trace: Trace,
    settings: SimulationSettings | None = None,
) -> SimulationResult:
    """Simulate ``model`` with ``params`` on ``trace``'s inputs and time grid.

    Parameters
    ----------
    model : CircuitModel
        The frozen model.
    params : ParameterSet or None
        Parameter values (engineering units); ``None`` for the defaults.
    trace : Trace
        Supplies time (s), current (mA), dither amplitude (mA) / frequency (Hz),
        line and prime pressure (bar) and oil temperature (°C).
    settings : SimulationSettings, optional
        Integrator, substeps, drive mode, tolerances.

    Returns
    -------
    SimulationResult

    Raises
    ------
    ModelError
        If an argument has the wrong type (``trace`` a Dataset, ``settings`` a dict, ...:
        the message names it), or ``params`` is not a :class:`ParameterSet` of ``model``
        (built for another model: the message lists the missing and extra parameter names).
    DataError
        If the trace has fewer than 2 samples, an input signal that is not finite (the
        message names it and its first bad sample) or metadata standing for an absent
        signal that is not a finite number — before anything is integrated.
    SimulationError
        If the state becomes non-finite (the message names the time), or, with
        ``settings.out_of_range == "raise"``, if a pressure leaves the range the circuit
        can reach.

    Warns
    -----
    SimulationWarning
        With ``settings.out_of_range == "warn"`` (the default), if a pressure leaves the
        range the circuit can reach (below −1 bar or above 1.5 × line pressure): a
        fixed-step (ROS2) result can be finite and still wrong by thousands of bar when the
        step is too long for the parameters' dynamics. The message names the output, its
        value and time, and the remedy (more ``substeps``, or ``method="radau"``).
    """
    _check_types(model, trace, settings)
    settings = settings or SimulationSettings()
    params = model_params(model, params)
    drive = choose_drive(trace, settings)
    u = input_matrix(trace, drive, settings)
    t0 = time.perf_counter()
    x, y = simulate_inputs(model, params, trace.time_s, u, drive, settings)
    wall = time.perf_counter() - t0
    fns = model.functions(drive)
    result = SimulationResult(
        time_s=np.asarray(trace.time_s, dtype=float),
        outputs={o.name: y[:, k] for k, o in enumerate(fns.outputs)},
        states=x,
        state_names=tuple(s.name for s in fns.states),
        state_units=tuple(s.unit for s in fns.states),
        output_specs=fns.outputs,
        params=params,
        drive=drive,
        trace_name=trace.name,
        wall_s=wall,
        inputs={s.name: u[:, k] for k, s in enumerate(MODEL_INPUTS)},
    )
    if settings.out_of_range == "raise":
        result.check_pressures()
    elif settings.out_of_range == "warn" and (why := result.out_of_range()) is not None:
        warnings.warn(why, SimulationWarning, stacklevel=2)
    return result


def _check_types(model, trace, settings) -> None:
    """ModelError naming the argument of :func:`simulate` that has the wrong type (they
    failed deep inside with an AttributeError such as "'Dataset' object has no attribute
    'has'")."""
    problems = []
    if not isinstance(model, CircuitModel):
        problems.append(f"model must be a CircuitModel, not {type(model).__name__}")
    if isinstance(trace, Dataset):
        problems.append(
            "trace must be one Trace, not a Dataset: simulate each experiment "
            "([simulate(model, params, tr) for tr in dataset]) or pick one (dataset['name'])"
        )
    elif not isinstance(trace, Trace):
        hint = " (Trace.from_pandas(df, name) builds one)" if hasattr(trace, "columns") else ""
        problems.append(f"trace must be a Trace, not {type(trace).__name__}{hint}")
    if settings is not None and not isinstance(settings, SimulationSettings):
        hint = " (SimulationSettings(**settings))" if isinstance(settings, dict) else ""
        problems.append(
            f"settings must be a SimulationSettings or None, not {type(settings).__name__}{hint}"
        )
    if problems:
        raise ModelError("simulate: " + "; ".join(problems))


def model_params(model: CircuitModel, params: ParameterSet | None) -> ParameterSet:
    """``params`` checked to be a parameter set of ``model`` (its defaults for None).

    Parameters
    ----------
    model : CircuitModel
        The model to simulate.
    params : ParameterSet or None
        Values in engineering units.

    Returns
    -------
    ParameterSet
        In ``model``'s parameter order (what its functions take by position).

    Raises
    ------
    ModelError
        If ``params`` is not a ParameterSet, or was built for a model with other
        parameters (the message lists the missing and extra names).
    """
    if params is None:
        return model.default_params()
    if not isinstance(params, ParameterSet):
        raise ModelError(
            f"params must be a ParameterSet (model.params(name=value, ...)), "
            f"not {type(params).__name__}"
        )
    effects = "effects " + ", ".join(model.effect_names) if model.effects else "no effects"
    return params.for_model(model.parameters, f"model {model.name!r} ({effects})")


def initial_state(fns: ModelFunctions, u0: np.ndarray) -> np.ndarray:
    """A starting guess: each state's declared initial value, current at its command."""
    x0 = np.array([s.initial for s in fns.states], dtype=float)
    names = [s.name for s in fns.states]
    if "i" in names:
        x0[names.index("i")] = max(u0[0], 0.0)
    return x0


def simulate_inputs(
    model: CircuitModel,
    params: ParameterSet,
    t: np.ndarray,
    u: np.ndarray,
    drive: str,
    settings: SimulationSettings,
    x0: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Core loop on an input matrix ``u`` (N × nu): returns states (N × nx) and outputs (N × ny).

    A settling run of ``settings.settle_s`` at the first sample's inputs (dither
    running) precedes the trace unless ``x0`` is given.

    Parameters
    ----------
    model : CircuitModel
        The frozen model.
    params : ParameterSet
        Values of ``model``'s parameters (engineering units).
    t : numpy.ndarray
        Sample times (s), N, non-decreasing.
    u : numpy.ndarray
        Inputs (N × nu) in :data:`~clutchlab.physics.assembly.MODEL_INPUTS` order and
        units (:func:`~clutchlab.physics.inputs.input_matrix`).
    drive : {"command", "measured"}
        Coil excitation.
    settings : SimulationSettings
        Integrator, substeps, settling time.
    x0 : numpy.ndarray, optional
        Initial state (scaled state units, nx); settled from a guess when None.

    Returns
    -------
    (numpy.ndarray, numpy.ndarray)
        States (N × nx) and outputs (N × ny) at the samples.

    Raises
    ------
    ModelError
        If ``params`` is not a parameter set of ``model``.
    SimulationError
        If ``t`` or ``u`` has the wrong shape or a non-finite value (named by input and
        sample, before anything is integrated), or the state becomes non-finite.
    """
    fns = model.functions(drive)
    p = model_params(model, params).vector()
    t = np.asarray(t, dtype=float)
    u = np.asarray(u, dtype=float)
    _check_inputs(t, u)
    # Coarse samples: the ROS2 step stays ≤ MAX_STEP_S on a finer grid (Radau is adaptive).
    parts = steps_per_interval(t, settings.substeps) if settings.method == "ros2" else None
    keep = None
    if parts is not None:
        t, u, keep = split_intervals(t, u, parts)
    if x0 is None:
        x0 = initial_state(fns, u[0])
        if settings.settle_s > 0:
            x0 = _settle(model, fns, p, t, u, drive, settings, x0)
    if settings.method == "radau":
        from .reference import integrate_radau

        x = integrate_radau(fns, p, t, u, x0, settings)
        y = np.asarray(fns.out.map(len(t))(x.T, u.T, p)).T
    else:
        x, y = _run_ros2(model, p, t, u, drive, settings, x0)
    bad = ~np.all(np.isfinite(x), axis=1)
    if bad.any():
        k = int(np.argmax(bad))
        sample = k if keep is None else int(np.searchsorted(keep, k))
        raise SimulationError(
            f"state not finite at t = {t[k]:.6g} s (sample {sample}); "
            "the integrator diverged for these parameters"
        )
    return (x, y) if keep is None else (x[keep], y[keep])


def _check_inputs(t: np.ndarray, u: np.ndarray) -> None:
    """SimulationError naming the first non-finite input (column and sample) or a bad shape."""
    names = [s.name for s in MODEL_INPUTS]
    if t.ndim != 1 or t.size == 0 or u.shape != (t.size, len(names)):
        raise SimulationError(
            f"inputs: t must be 1-D with N ≥ 1 samples and u N × {len(names)} "
            f"({', '.join(names)}); got t {t.shape}, u {u.shape}"
        )
    problems = []
    bad_t = np.flatnonzero(~np.isfinite(t))
    if bad_t.size:
        problems.append(f"t is {t[bad_t[0]]} at sample {int(bad_t[0])}")
    elif np.any(np.diff(t) < 0):
        problems.append(f"t decreases at sample {int(np.argmax(np.diff(t) < 0)) + 1}")
    bad = ~np.isfinite(u)
    for k in np.flatnonzero(bad.any(axis=0)):
        row = int(np.argmax(bad[:, k]))
        problems.append(f"input {names[k]} is {u[row, k]} at t = {t[row]:.6g} s (sample {row})")
    if problems:
        raise SimulationError("bad inputs, nothing integrated: " + "; ".join(problems))


def _settle(model, fns, p, t, u, drive, settings, x0):
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1e-3
    if dt > COARSE_INTERVAL_S:  # its ROS2 steps ≤ MAX_STEP_S, as on the trace
        dt = min(dt, settings.substeps * MAX_STEP_S)
    n = max(2, round(settings.settle_s / dt) + 1)
    us = np.repeat(u[:1], n, axis=0)
    freq = u[0, [s.name for s in MODEL_INPUTS].index("dither_freq_Hz")]
    k_phase = [s.name for s in MODEL_INPUTS].index("dither_phase")
    # Phase runs so that the settling run ends at the trace's first phase.
    us[:, k_phase] = u[0, k_phase] + freq * dt * (np.arange(n) - (n - 1))
    ts = t[0] + dt * (np.arange(n) - (n - 1))
    x, _ = _run_ros2(model, p, ts, us, drive, settings, x0)
    return x[-1]


def _run_ros2(model, p, t, u, drive, settings, x0):
    n = len(t)
    fn = DenseCall(
        chunk_function(model, drive, settings.substeps, settings.chunk, settings.compile)
    )
    fn.fix(p=p)
    u0, u1 = interval_inputs(u)
    dt = np.diff(t)
    nx = len(x0)
    x = np.empty((n, nx))
    x[0] = x0
    y0 = np.asarray(model.functions(drive).out(x0, u[0], p)).ravel()
    y = np.empty((n, len(y0)))
    y[0] = y0
    k, xk, m = 0, np.asarray(x0, dtype=float), settings.chunk
    while k < n - 1:
        cnt = min(m, n - 1 - k)
        a0 = np.zeros((u.shape[1], m))
        a1 = np.zeros((u.shape[1], m))
        dts = np.full((1, m), dt[k] if cnt else 1e-3)
        a0[:, :cnt], a1[:, :cnt], dts[0, :cnt] = (
            u0[k : k + cnt].T,
            u1[k : k + cnt].T,
            dt[k : k + cnt],
        )
        if cnt < m:  # pad with the last inputs, zero-length intervals
            a0[:, cnt:], a1[:, cnt:] = a1[:, cnt - 1 : cnt], a1[:, cnt - 1 : cnt]
            dts[0, cnt:] = 0.0
        xs, ys = fn(x0=xk, u0=a0, u1=a1, dt=dts)
        x[k + 1 : k + 1 + cnt] = xs[:, :cnt].T
        y[k + 1 : k + 1 + cnt] = ys[:, :cnt].T
        xk = xs[:, cnt - 1].copy()
        if not np.all(np.isfinite(xk)):
            break
        k += cnt
    return x, y
