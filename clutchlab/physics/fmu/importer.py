"""A vendor FMU as the physics model: :class:`FmuPhysics` (``predict(trace) -> bar``).

The FMU runs on the trace's own time grid through FMPy's FMI 2.0 co-simulation API: one
``fmi2DoStep`` per sample interval, inputs set at each sample. When the FMU can
interpolate inputs (``canInterpolateInputs``), each input's slope over the interval is
set as its derivative, so the inputs are linear over a step, as in clutchlab's own
simulator; otherwise they are held over the step (as ``fmpy.simulate_fmu`` does).
"""

from __future__ import annotations

import ctypes
import hashlib
import multiprocessing as mp
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from sklearn.base import BaseEstimator

from ...data import Trace
from ...data.signals import SIGNALS
from ...errors import SimulationError
from ..integrator import cache_dir
from .errors import FmuError, FmuTimeoutError
from .inspect import CURRENT_SIGNALS, FmuInterface, inspect_fmu

__all__ = ["FmuPhysics", "FmuSimulation"]

_WAVES = ("sine", "triangle", "square")
_FMI2_WARNING = 1
#: Extra wall time (s) granted to an isolated run for starting the child interpreter and
#: loading and initializing the FMU, before its stepping (and so its clock) starts.
SPAWN_ALLOWANCE_S = 30.0
#: Wall time (s) the parent waits past ``timeout_s`` once the child reported that its
#: stepping started: the child's own check (between steps) normally fires first.
KILL_MARGIN_S = 1.0


@dataclass
class FmuSimulation:
    """An FMU run on one trace.

    Attributes
    ----------
    time_s : ndarray
        The trace's sample times (s).
    outputs : dict
        Every Real output of the FMU on that grid, in the FMU's units.
    pressure_bar : ndarray
        The clutch-pressure output converted to bar.
    sources : dict
        FMU input → where its values came from (``"trace:<signal>"``, ``"meta:<key>"``,
        ``"default:<value>"``, ``"start:<value>"``).
    start_values : dict
        Parameters set before initialization.
    wall_s : float
        Wall time of the run (s).
    trace_name : str
        The trace simulated.
    fmu : str
        The FMU file.
    """

    time_s: np.ndarray
    outputs: dict[str, np.ndarray]
    pressure_bar: np.ndarray
    sources: dict[str, str]
    start_values: dict[str, float]
    wall_s: float
    trace_name: str
    fmu: str
    messages: list[str] = field(default_factory=list)

    def to_pandas(self) -> pd.DataFrame:
        """Outputs as a DataFrame indexed by time (s)."""
        return pd.DataFrame(self.outputs, index=pd.Index(self.time_s, name="time_s"))


def _signal_values(trace: Trace, port, fallback_start: bool) -> tuple[np.ndarray, str]:
    name = port.signal
    if trace.has(name):
        return np.asarray(trace.get(name), dtype=float), f"trace:{name}"
    if name in CURRENT_SIGNALS:
        raise FmuError(
            f"trace {trace.name!r} has no {name} for FMU input {port.name!r} "
            f"(its signals: {', '.join(trace.signals)})"
        )
    meta = trace.meta.get(name)
    if isinstance(meta, int | float) and not isinstance(meta, bool):
        return np.full(len(trace), float(meta)), f"meta:{name}"
    default = SIGNALS[name].default
    if default is not None:
        return np.full(len(trace), float(default)), f"default:{default:g}"
    if fallback_start and port.start is not None:
        value = float(port.from_fmu(port.start))
        return np.full(len(trace), value), f"start:{value:g}"
    raise FmuError(
        f"trace {trace.name!r} has no {name} for FMU input {port.name!r}, and the input "
        "declares no start value"
    )


class FmuPhysics(BaseEstimator):
    """A physics baseline from an FMU (FMI 2.0 co-simulation), e.g. exported from Amesim.

    Usable wherever a physics model with ``predict(trace)`` is expected (the hybrid
    trainer, the validation report).

    Parameters
    ----------
    fmu : path-like
        The ``.fmu`` file.
    input_map : dict, optional
        FMU input name → canonical signal name, for inputs not named after the canonical
        signals; units are converted through the FMU's unit definitions.
    output : str, optional
        FMU output with the clutch pressure (default ``clutch_pressure_bar``, else the
        only Real output).
    start_values : dict, optional
        FMU parameter name → value (in the FMU's unit), set before initialization.
    parameters : dict, optional
        The same as ``start_values`` (the name vendor tools use); both may be given, a
        parameter in both with two values is an error. A value must be a finite number
        inside the parameter's declared ``min`` / ``max``. Every parameter left at the
        FMU's own start value is listed in each simulation's messages and in
        :meth:`parameter_summary`.
    timeout_s : float
        Wall-time limit of one trace's simulation (s), from its first step; an isolated
        run is granted :data:`SPAWN_ALLOWANCE_S` more for starting its process and loading
        and initializing the FMU, and is killed :data:`KILL_MARGIN_S` past the limit once
        it is stepping.
    isolate : bool
        Run the FMU in a child process (forked: ~15 ms per trace), killed at the timeout:
        an FMU that hangs inside one step or crashes gives a clear error instead of hanging
        or killing this process (default). Without it the limit is checked between steps.
    use_start_values : bool
        Feed an input whose signal the trace lacks (and which has no default) with the
        FMU's start value; otherwise that is an error. The current is never defaulted.
    name : str, optional
        Name in reports; default the FMU's file stem.

    Raises
    ------
    FmuError
        At construction, when the file is not a usable FMI 2.0 co-simulation FMU or its
        interface does not fit, or a parameter value is unknown, not finite or outside
        the FMU's declared range (every problem listed).

    Examples
    --------
    >>> physics = FmuPhysics("amesim_clutch.fmu", input_map={"I_cmd": "current_cmd_mA"})
    >>> pressure = physics.predict(trace)  # doctest: +SKIP
    """

    def __init__(
        self,
        fmu: str | Path,
        input_map: dict[str, str] | None = None,
        output: str | None = None,
        start_values: dict[str, float] | None = None,
        timeout_s: float = 600.0,
        isolate: bool = True,
        use_start_values: bool = True,
        name: str | None = None,
        parameters: dict[str, float] | None = None,
    ) -> None:
        # Arguments are stored as given (scikit-learn's clone() checks identity).
        self.fmu = fmu
        self.input_map = input_map
        self.output = output
        self.start_values = start_values
        self.timeout_s = timeout_s
        self.isolate = isolate
        self.use_start_values = use_start_values
        self.name = name
        self.parameters = parameters
        self.interface_: FmuInterface = inspect_fmu(Path(fmu), input_map, output)
        given = self._given_parameters()
        unknown = sorted(set(given) - set(self.interface_.parameters))
        if unknown:
            raise FmuError(
                f"{fmu}: start_values for unknown parameter(s) {', '.join(unknown)}; "
                f"its parameters: {', '.join(self.interface_.parameters) or 'none'}"
            )
        bad = _out_of_range(self._declared(), given)
        if bad:
            raise FmuError(f"{fmu}: parameter value(s) the FMU does not accept", bad)

    def _declared(self) -> dict[str, tuple[float | None, float | None, float | None, str]]:
        """Every parameter: name → (start, min, max, unit) as declared (None: absent)."""
        out = {}
        for v in self.interface_.model_description.modelVariables:
            if v.causality == "parameter":
                out[v.name] = (
                    _number(v.start),
                    _number(v.min),
                    _number(v.max),
                    str(v.unit or getattr(v.declaredType, "unit", None) or ""),
                )
        return out

    def parameter_summary(self) -> dict[str, dict[str, float | None]]:
        """Which parameters the simulations set, and which keep the FMU's start value.

        Returns
        -------
        dict
            ``"set"``: name → value given (``parameters`` / ``start_values``, in the FMU's
            unit); ``"from_trace"``: name → None for a clutchlab FMU's trace-dependent
            parameters, set from each trace (dither waveform weights, settling step) unless
            given; ``"start_value"``: name → the FMU's declared start value of every other
            parameter.
        """
        given = self._given_parameters()
        itf = self.interface_
        from_trace = set()
        if itf.clutchlab:
            from_trace = {f"dither_wave_{w}" for w in _WAVES} | {"settle_step_s"}
            from_trace &= set(itf.parameters)
        declared = self._declared()
        return {
            "set": {k: float(v) for k, v in given.items()},
            "from_trace": {k: None for k in itf.parameters if k in from_trace and k not in given},
            "start_value": {
                k: declared.get(k, (None,))[0]
                for k in itf.parameters
                if k not in given and k not in from_trace
            },
        }

    def _given_parameters(self) -> dict[str, float]:
        """``start_values`` and ``parameters`` merged; a clash of values is an error."""
        a, b = dict(self.start_values or {}), dict(self.parameters or {})
        clash = sorted(k for k in set(a) & set(b) if a[k] != b[k])
        if clash:
            raise FmuError(
                f"{self.fmu}: parameter(s) {', '.join(clash)} given twice with different "
                "values (start_values and parameters)"
            )
        return a | b

    @property
    def label(self) -> str:
        """Name in reports: ``name``, else the FMU's file stem."""
        return self.name or Path(self.fmu).stem

    # ---- the protocol of a physics model ------------------------------------------------
    def fit(self, data=None) -> FmuPhysics:
        """Nothing to fit: an FMU is used as given. Returns ``self``."""
        return self

    def predict(self, trace: Trace) -> np.ndarray:
        """Clutch pressure (bar) of the FMU on ``trace``'s inputs and time grid."""
        return self.simulate(trace).pressure_bar

    def predict_outputs(self, trace: Trace) -> dict[str, np.ndarray]:
        """Every Real output of the FMU on ``trace`` (name → per-sample array).

        ``clutch_pressure_bar`` is the pressure output in bar (whatever the FMU calls it);
        the others keep the FMU's names and units — for a clutchlab FMU those of
        :data:`clutchlab.physics.OUTPUTS` (``pilot_pressure_bar`` …), as a hybrid model's
        physics features expect.
        """
        sim = self.simulate(trace)
        return {**sim.outputs, "clutch_pressure_bar": sim.pressure_bar}

    # ---- simulation ----------------------------------------------------------------------
    def _trace_start_values(self, trace: Trace) -> dict[str, float]:
        """Parameters of a clutchlab FMU that describe the trace (waveform, settling step)."""
        itf = self.interface_
        out: dict[str, float] = {}
        if not itf.clutchlab:
            return out
        wave = str(trace.meta.get("dither_waveform", "sine"))
        if wave in _WAVES and all(f"dither_wave_{w}" in itf.parameters for w in _WAVES):
            out |= {f"dither_wave_{w}": float(w == wave) for w in _WAVES}
        if "settle_step_s" in itf.parameters and len(trace) > 1:
            out["settle_step_s"] = float(np.median(np.diff(trace.time_s)))
        return out

    def _inputs(self, trace: Trace) -> tuple[np.ndarray, dict[str, str]]:
        itf = self.interface_
        cols, sources = [], {}
        for port in itf.inputs:
            values, src = _signal_values(trace, port, self.use_start_values)
            cols.append(port.to_fmu(values))
            sources[port.name] = src
        return np.column_stack(cols) if cols else np.zeros((len(trace), 0)), sources

    def simulate(self, trace: Trace) -> FmuSimulation:
        """Run the FMU on ``trace``: every Real output on the trace's time grid.

        Raises
        ------
        FmuError
            A signal the FMU needs is missing from the trace.
        FmuTimeoutError
            The run exceeded ``timeout_s``.
        SimulationError
            The FMU reported an error (its log messages are in the message).
        """
        u, sources = self._inputs(trace)
        starts = self._trace_start_values(trace) | self._given_parameters()
        t = np.asarray(trace.time_s, dtype=float)
        job = _Job(
            fmu=str(self.fmu),
            unzipdir=str(_extracted(Path(self.fmu))),
            guid=self.interface_.model_description.guid,
            model_identifier=self.interface_.model_description.coSimulation.modelIdentifier,
            t=t,
            u=u,
            in_vrs=[p.value_reference for p in self.interface_.inputs],
            out_names=list(self.interface_.outputs),
            out_vrs=list(self.interface_.outputs.values()),
            par_vrs=[self.interface_.parameters[k] for k in starts],
            par_values=list(starts.values()),
            derivatives=self.interface_.can_interpolate_inputs,
            timeout_s=float(self.timeout_s),
            trace_name=trace.name,
        )
        t0 = time.perf_counter()
        y, messages = _run_isolated(job) if self.isolate else _run(job)
        messages = (
            [f"input {name!r} not fed ({why})" for name, why in self.interface_.unfed.items()]
            + [
                f"parameter {name!r} left at the FMU's start value"
                for name in self.interface_.parameters
                if name not in starts
            ]
            + list(messages)
        )
        wall = time.perf_counter() - t0
        outputs = {n: y[:, k] for k, n in enumerate(job.out_names)}
        pressure = self.interface_.output.from_fmu(outputs[self.interface_.output.name])
        return FmuSimulation(
            time_s=t,
            outputs=outputs,
            pressure_bar=np.asarray(pressure, dtype=float),
            sources=sources,
            start_values=starts,
            wall_s=wall,
            trace_name=trace.name,
            fmu=str(self.fmu),
            messages=messages,
        )


def _number(text) -> float | None:
    """A declared attribute (FMPy keeps it as text) as a float; None when absent."""
    if text is None or text == "":
        return None
    try:
        return float(text)
    except (TypeError, ValueError):
        return None


def _out_of_range(declared: dict, given: dict[str, float]) -> list[str]:
    """Problems of ``given`` parameter values against the declared ``min`` / ``max``."""
    problems = []
    for name, value in given.items():
        _, lo, hi, unit = declared.get(name, (None, None, None, ""))
        unit = f" {unit}" if unit else ""
        try:
            x = float(value)
        except (TypeError, ValueError):
            problems.append(f"{name} = {value!r}: not a number")
            continue
        if not np.isfinite(x):
            problems.append(f"{name} = {value!r}: not a finite number")
        elif (lo is not None and x < lo) or (hi is not None and x > hi):
            span = f"[{'-inf' if lo is None else f'{lo:g}'}, {'inf' if hi is None else f'{hi:g}'}]"
            problems.append(
                f"{name} = {x:g}{unit}: outside the FMU's declared range {span}{unit} "
                "(min / max in modelDescription.xml)"
            )
    return problems


def _extracted(path: Path) -> Path:
    """The FMU extracted once into the cache (keyed by the file's hash), within the limits.

    Members are streamed out with their bytes counted (a member's header is not trusted),
    into a temporary folder that is renamed into place only when complete and removed on
    any failure, so the cache never holds a partial or oversized extraction.
    """
    import shutil
    import tempfile
    import zipfile

    from .inspect import FmuLimits, check_archive

    digest = hashlib.sha1(path.read_bytes()).hexdigest()[:16]
    folder = cache_dir() / "fmu_extracted" / f"{path.stem}_{digest}"
    if (folder / "modelDescription.xml").exists():
        return folder
    limits = FmuLimits.from_env()
    folder.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", dir=folder.parent))
    try:
        with zipfile.ZipFile(path) as zf:
            total = 0
            for info in check_archive(path, zf, limits):
                target = tmp / info.filename
                if info.is_dir():
                    target.mkdir(parents=True, exist_ok=True)
                    continue
                target.parent.mkdir(parents=True, exist_ok=True)
                with zf.open(info) as src, open(target, "wb") as dst:
                    while chunk := src.read(1 << 20):
                        total += len(chunk)
                        if total > limits.max_total_bytes:
                            raise FmuError(
                                f"{path}: more than {limits.max_total_bytes} bytes when "
                                "extracted (raise CLUTCHLAB_FMU_MAX_TOTAL_BYTES if genuine)"
                            )
                        dst.write(chunk)
        try:
            tmp.rename(folder)
        except OSError:  # another process extracted it meanwhile
            shutil.rmtree(tmp, ignore_errors=True)
    except (zipfile.BadZipFile, NotImplementedError, EOFError) as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        raise FmuError(f"{path}: damaged zip archive: {exc}") from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return folder


@dataclass
class _Job:
    fmu: str
    unzipdir: str
    guid: str
    model_identifier: str
    t: np.ndarray
    u: np.ndarray
    in_vrs: list[int]
    out_names: list[str]
    out_vrs: list[int]
    par_vrs: list[int]
    par_values: list[float]
    derivatives: bool
    timeout_s: float
    trace_name: str


def _run(job: _Job, started=None) -> tuple[np.ndarray, list[str]]:
    """The stepping loop, through FMPy's FMU2Slave and its ctypes functions.

    ``started``, if given, is called when the stepping (and its clock) starts."""
    from fmpy import calloc, free
    from fmpy.fmi2 import (
        FMU2Slave,
        fmi2CallbackAllocateMemoryTYPE,
        fmi2CallbackFreeMemoryTYPE,
        fmi2CallbackFunctions,
        fmi2CallbackLoggerTYPE,
    )

    messages: list[str] = []

    def logger(env, instance, status, category, message):
        text = message.decode("utf-8", "replace").replace("%%", "%") if message else ""
        messages.append(
            f"[{['OK', 'WARNING', 'DISCARD', 'ERROR', 'FATAL', 'PENDING'][status]}] {text}"
        )

    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(logger)
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    # No fmpy.logging.addLoggerProxy: it keeps the Python logger in one process-global
    # slot, which this short-lived callback would leave dangling. Messages therefore
    # arrive unformatted when an FMU passes variadic arguments (clutchlab FMUs do not).

    t, u = job.t, job.u
    n, nu, ny = len(t), len(job.in_vrs), len(job.out_vrs)
    dt = np.diff(t)
    du = np.diff(u, axis=0) / dt[:, None] if n > 1 else np.zeros((0, nu))

    def err(what: str, exc: Exception | None = None) -> SimulationError:
        tail = "\n".join(messages[-10:])
        text = f"FMU {job.fmu} on {job.trace_name}: {what}" + (f" ({exc})" if exc else "")
        return SimulationError(text + (f"\nFMU log:\n{tail}" if tail else ""))

    try:
        fmu = FMU2Slave(
            guid=job.guid,
            unzipDirectory=job.unzipdir,
            modelIdentifier=job.model_identifier,
            instanceName="clutchlab",
        )
    except Exception as exc:
        raise FmuError(f"{job.fmu}: the binary cannot be loaded: {exc}") from exc
    fn = fmu._functions
    set_real, get_real = fn["fmi2SetReal"], fn["fmi2GetReal"]
    set_der, do_step = fn["fmi2SetRealInputDerivatives"], fn["fmi2DoStep"]
    vr_in = (ctypes.c_uint32 * max(nu, 1))(*job.in_vrs)
    vr_out = (ctypes.c_uint32 * ny)(*job.out_vrs)
    order = (ctypes.c_int * max(nu, 1))(*([1] * nu))
    val_in = (ctypes.c_double * max(nu, 1))()
    der_in = (ctypes.c_double * max(nu, 1))()
    val_out = (ctypes.c_double * ny)()
    v_in = np.ctypeslib.as_array(val_in)
    d_in = np.ctypeslib.as_array(der_in)
    v_out = np.ctypeslib.as_array(val_out)
    y = np.empty((n, ny))
    instantiated = False
    try:
        try:
            fmu.instantiate(callbacks=callbacks)
            instantiated = True
            fmu.setupExperiment(startTime=float(t[0]))
            if job.par_vrs:
                fmu.setReal(job.par_vrs, job.par_values)
            fmu.enterInitializationMode()
            if nu:
                v_in[:nu] = u[0]
                set_real(fmu.component, vr_in, nu, val_in)
                if job.derivatives and n > 1:
                    d_in[:nu] = du[0]
                    set_der(fmu.component, vr_in, nu, order, der_in)
            fmu.exitInitializationMode()
        except Exception as exc:
            raise err("initialization failed", exc) from exc
        if get_real(fmu.component, vr_out, ny, val_out) > _FMI2_WARNING:
            raise err("fmi2GetReal failed")
        y[0] = v_out
        if started is not None:
            started()
        t_start = time.perf_counter()
        for k in range(n - 1):
            status = do_step(fmu.component, float(t[k]), float(dt[k]), 1)
            if status > _FMI2_WARNING:
                raise err(f"fmi2DoStep at t = {t[k]:.6g} s failed (status {status})")
            # The inputs of the new communication point are set before its outputs are read,
            # so a direct-feedthrough output follows its input without a one-step lag.
            if nu:
                v_in[:nu] = u[k + 1]
                status = set_real(fmu.component, vr_in, nu, val_in)
                if job.derivatives and k + 1 < n - 1:
                    d_in[:nu] = du[k + 1]
                    status = max(status, set_der(fmu.component, vr_in, nu, order, der_in))
                if status > _FMI2_WARNING:
                    raise err(f"setting the inputs at t = {t[k + 1]:.6g} s failed")
            if get_real(fmu.component, vr_out, ny, val_out) > _FMI2_WARNING:
                raise err(f"fmi2GetReal at t = {t[k + 1]:.6g} s failed")
            y[k + 1] = v_out
            if (k & 255) == 0 and time.perf_counter() - t_start > job.timeout_s:
                raise FmuTimeoutError(
                    f"FMU {job.fmu} on {job.trace_name}: timeout after {job.timeout_s:g} s "
                    f"at t = {t[k + 1]:.6g} s of {t[-1]:.6g} s"
                )
        try:
            fmu.terminate()
        except Exception as exc:
            raise err("fmi2Terminate failed", exc) from exc
    finally:
        if instantiated:
            fmu.freeInstance()
        else:
            fmu.freeLibrary()
    return y, messages


def _child(conn, job: _Job) -> None:  # pragma: no cover - runs in the child process
    import faulthandler

    faulthandler.disable()  # a crashing FMU is reported by the parent, not dumped here
    try:
        conn.send(("ok", _run(job, started=lambda: conn.send(("started", None)))))
    except BaseException as exc:
        conn.send(("error", exc))
    finally:
        conn.close()


def _run_isolated(job: _Job) -> tuple[np.ndarray, list[str]]:
    """:func:`_run` in a child process (forked where possible), killed at ``job.timeout_s``."""
    ctx = mp.get_context("fork" if "fork" in mp.get_all_start_methods() else "spawn")
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(child, job), daemon=True)
    proc.start()
    child.close()
    try:
        # Starting the child, loading and initializing the FMU: the allowance; once the child
        # says its stepping started, the timeout (plus a margin for its own check).
        wait = job.timeout_s + SPAWN_ALLOWANCE_S
        while True:
            if not parent.poll(wait):
                proc.kill()
                proc.join()
                raise FmuTimeoutError(
                    f"FMU {job.fmu} on {job.trace_name}: timeout after {job.timeout_s:g} s "
                    "(child process killed)"
                )
            try:
                kind, payload = parent.recv()
            except EOFError:
                proc.join()
                raise SimulationError(
                    f"FMU {job.fmu} on {job.trace_name}: the FMU process died "
                    f"(exit code {proc.exitcode})"
                ) from None
            if kind != "started":
                break
            wait = job.timeout_s + KILL_MARGIN_S
    finally:
        parent.close()
        proc.join(timeout=5)
    if kind == "error":
        raise payload
    return payload
