"""Forward parameter (and initial-state) sensitivities of the sampled model output.

The ROS2 sample step is differentiated symbolically (forward mode, ``nd``
directions at once) and mapped over chunks of samples in compiled C, like the
plain simulation. Directions are seeded by inputs — ``S0`` (nx × nd, initial
state) and ``E`` (np × nd, parameters) — so one compiled function serves every
choice of free parameters and both single and multiple shooting.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np

from ...errors import SimulationError
from ..dense_call import DenseCall
from ..inputs import choose_drive, interval_inputs, split_intervals
from ..integrator import (
    CSE,
    chunk_function,
    compile_in_background,
    load_or_compile,
    recorded_library,
    sample_step_function,
)
from ..model import CircuitModel
from ..settings import SimulationSettings, steps_per_interval
from ..source_key import code_source_key

__all__ = [
    "SENSITIVITY_CHUNK",
    "SensitivityRun",
    "compile_sensitivities_for",
    "compile_sensitivities_in_background",
    "sensitivity_chunk",
    "simulate_sensitivities",
]


@lru_cache(maxsize=32)
def _mapped(model: CircuitModel, drive: str, substeps: int, nd: int, chunk: int):
    """The uncompiled sensitivity loop over ``chunk`` samples, and its cache tag (built once
    per process: a background build and the later load share it)."""
    fns = model.functions(drive)
    step = sample_step_function(fns, substeps)
    nx, nu, npar = fns.nx, fns.u_sym.shape[0], fns.p_sym.shape[0]
    x0, s0 = ca.SX.sym("x0", nx), ca.SX.sym("S0", nx, nd)
    u0, u1, dt = ca.SX.sym("u0", nu), ca.SX.sym("u1", nu), ca.SX.sym("dt")
    p, e = ca.SX.sym("p", npar), ca.SX.sym("E", npar, nd)
    x1, y1 = step(x0, u0, u1, dt, p)
    z, seed = ca.vertcat(x0, p), ca.vertcat(s0, e)
    s1 = ca.jtimes(x1, z, seed)
    dy1 = ca.jtimes(y1[0], z, seed)
    fn = ca.Function(
        "sens_step",
        [x0, s0, u0, u1, dt, p, e],
        [x1, s1, y1[0], dy1.T],
        ["x0", "S0", "u0", "u1", "dt", "p", "E"],
        ["x1", "S1", "y1", "dy1"],
        CSE,
    )
    name, tag = _names(model, drive, substeps, nd, chunk)
    return fn.mapaccum(name, chunk, ["x0", "S0"], ["x1", "S1"]), tag


def _names(model: CircuitModel, drive: str, substeps: int, nd: int, chunk: int):
    """Name of the compiled sensitivity loop and its cache tag."""
    return f"sens_chunk_{chunk}", f"clutchlab_sens_{model.key}_{drive}_{substeps}_{nd}"


#: Samples per call of the compiled sensitivity loop (what the fit problem uses).
SENSITIVITY_CHUNK = 500

#: -O1: the derivative code is large; -O3 compiles ~10x longer for no speed-up here.
_OPT = "-O1"


@lru_cache(maxsize=32)
def sensitivity_chunk(
    model: CircuitModel, drive: str, substeps: int, nd: int, chunk: int, compile_mode: str = "auto"
) -> ca.Function:
    """``sens(x0, S0, U0, U1, DT, p, E) -> (X, S, Y, DY)`` over ``chunk`` samples.

    ``X`` (nx × chunk) states, ``S`` (nx × nd·chunk) their sensitivities, ``Y``
    (1 × chunk) the sensor pressure (bar), ``DY`` (nd × chunk) its sensitivities,
    all at the interval ends.
    """
    if compile_mode == "never":
        return _mapped(model, drive, substeps, nd, chunk)[0]
    name, tag = _names(model, drive, substeps, nd, chunk)
    return load_or_compile(
        model, name, tag, _OPT, lambda: _mapped(model, drive, substeps, nd, chunk)[0]
    )[0]


def compile_sensitivities_in_background(
    model: CircuitModel, drive: str, substeps: int, nd: int, chunk: int
) -> None:
    """Start compiling :func:`sensitivity_chunk`'s code into the cache and return at once.

    For a model that will be needed later (the next candidate's refit): its C code
    compiles on the other core while this process works on, and the later
    :func:`sensitivity_chunk` waits for that build instead of starting its own.
    """
    name, tag = _names(model, drive, substeps, nd, chunk)
    if recorded_library(tag, code_source_key(model, name, tag, _OPT)) is None:
        compile_in_background(*_mapped(model, drive, substeps, nd, chunk), _OPT)


def compile_sensitivities_for(
    model: CircuitModel,
    traces,
    substeps: int,
    drive: str,
    nd: int,
    background: bool = False,
) -> None:
    """Compile (or load from the cache) ``model``'s sensitivity code for ``nd`` directions,
    for every drive mode that ``traces`` are simulated with.

    Parameters
    ----------
    model : CircuitModel
        Model structure.
    traces : sequence of Trace
        Experiments (their drive mode decides which code is needed).
    substeps : int
        ROS2 substeps per sample.
    drive : str
        The fit's drive setting (``auto``, ``measured`` or ``command``).
    nd : int
        Number of sensitivity directions (free parameters, single shooting).
    background : bool
        Only start compiling what is not cached (on another core, while this process
        works on) and return at once; the later foreground call waits for it.
    """
    for mode in _drive_modes(traces, SimulationSettings(substeps=substeps, drive=drive)):
        if background:
            compile_sensitivities_in_background(model, mode, substeps, nd, SENSITIVITY_CHUNK)
        else:
            sensitivity_chunk(model, mode, substeps, nd, SENSITIVITY_CHUNK)


def compile_fit_code(model: CircuitModel, traces, substeps: int, drive: str, nd: int) -> None:
    """Compile (or load from the cache) all the code a fit of ``model`` on ``traces`` runs:
    the simulation chunk and the sensitivity code for ``nd`` directions, for every drive
    mode of ``traces``, in this process.

    A stage limited by wall time calls this before its clock starts, so that what it
    computes does not depend on whether the compile cache was warm (see
    :func:`~clutchlab.physics.fit.staged.staged_start`). Parameters as
    :func:`compile_sensitivities_for`.
    """
    sim = SimulationSettings(substeps=substeps, drive=drive)
    for mode in _drive_modes(traces, sim):
        chunk_function(model, mode, substeps, sim.chunk, sim.compile)
        sensitivity_chunk(model, mode, substeps, nd, SENSITIVITY_CHUNK)


def _drive_modes(traces, sim: SimulationSettings) -> list[str]:
    """The drive modes ``traces`` are simulated with under ``sim``'s drive setting."""
    return sorted({choose_drive(t, sim) for t in traces})


@dataclass(frozen=True)
class SensitivityRun:
    """States, sensor output and their sensitivities along one trace."""

    x: np.ndarray  # N × nx
    y: np.ndarray  # N, bar
    dy: np.ndarray  # N × nd
    s_end: np.ndarray  # nx × nd: state sensitivities at the last sample


def simulate_sensitivities(
    model: CircuitModel,
    drive: str,
    substeps: int,
    t: np.ndarray,
    u: np.ndarray,
    p: np.ndarray,
    x0: np.ndarray,
    s0: np.ndarray,
    e: np.ndarray,
    chunk: int = SENSITIVITY_CHUNK,
    compile_mode: str = "auto",
) -> SensitivityRun:
    """Simulate from ``x0`` and propagate the sensitivity seeds ``s0`` (nx × nd), ``e`` (np × nd).

    Returns the sensor pressure and its derivative along every direction at each
    sample (the first sample's output derivative is ``∂y/∂x0 · s0``, evaluated by
    one zero-length step). Samples coarser than 1 kHz are integrated on a finer grid
    (:func:`~clutchlab.physics.settings.steps_per_interval`), as :func:`simulate_inputs`
    does.
    """
    nd = s0.shape[1]
    fn = DenseCall(sensitivity_chunk(model, drive, substeps, nd, chunk, compile_mode))
    # Coarse samples: the ROS2 step bounded as in simulate_inputs, so the derivatives are
    # those of the residuals the fit's forward runs compute (1 kHz and faster: unchanged).
    parts = steps_per_interval(t, substeps)
    keep = None
    if parts is not None:
        t, u, keep = split_intervals(np.asarray(t, float), np.asarray(u, float), parts)
    u0, u1 = interval_inputs(u)
    dts = np.diff(t)
    n = len(t)
    nx = len(x0)
    xs = np.empty((n, nx))
    ys = np.empty(n)
    dys = np.empty((n, nd))
    # Sample 0: a zero-length step returns the output and its derivative at x0.
    a0 = np.repeat(u[:1].T, chunk, axis=1)
    fn.fix(p=p, E=e)
    r = fn(x0=x0, S0=s0, u0=a0, u1=a0, dt=np.zeros((1, chunk)))
    xs[0], ys[0], dys[0] = x0, float(r[2][0, 0]), np.asarray(r[3])[:, 0]
    xk, sk, k = np.asarray(x0, float), np.asarray(s0, float), 0
    while k < n - 1:
        cnt = min(chunk, n - 1 - k)
        b0 = np.empty((u.shape[1], chunk))
        b1 = np.empty((u.shape[1], chunk))
        d = np.zeros((1, chunk))
        b0[:, :cnt], b1[:, :cnt], d[0, :cnt] = (
            u0[k : k + cnt].T,
            u1[k : k + cnt].T,
            dts[k : k + cnt],
        )
        if cnt < chunk:
            b0[:, cnt:] = b1[:, cnt - 1 : cnt]
            b1[:, cnt:] = b1[:, cnt - 1 : cnt]
        xc, sc, yc, dyc = fn(x0=xk, S0=sk, u0=b0, u1=b1, dt=d)
        xs[k + 1 : k + 1 + cnt] = xc[:, :cnt].T
        ys[k + 1 : k + 1 + cnt] = yc[0, :cnt]
        dys[k + 1 : k + 1 + cnt] = dyc[:, :cnt].T
        xk = xc[:, cnt - 1].copy()
        sk = sc[:, (cnt - 1) * nd : cnt * nd].copy()
        if not (np.all(np.isfinite(xk)) and np.all(np.isfinite(sk))):
            raise SimulationError(f"state or sensitivity not finite at t = {t[k + cnt]:.6g} s")
        k += cnt
    if keep is not None:
        xs, ys, dys = xs[keep], ys[keep], dys[keep]
    return SensitivityRun(xs, ys, dys, sk)
