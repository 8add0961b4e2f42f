"""Shared material of the FMU tests: a "fitted" model, its FMUs (built once per session),
stand traces, and tools to make broken FMUs out of a good one."""

from __future__ import annotations

import re
import shutil
import tempfile
import zipfile
from functools import lru_cache
from pathlib import Path

import fmpy
import numpy as np
from fit_support import synthetic_fit

from clutchlab.physics.fit import FitResult
from clutchlab.physics.fmu import export_physics_fmu
from clutchlab.physics.stand import RAMPS, DitherSetting, StandConfig, run_stand

#: A parameter set off the datasheet values, standing in for a fit result.
FITTED = {"vfs_K_m": 14.7, "reg_F_c": 1.08, "latch_F0": 28.6, "vfs_d_orf": 0.43, "reg_F0": -1.7}

TMP = Path(tempfile.mkdtemp(prefix="clutchlab-fmu-tests-"))


def fit_result(effects: tuple[str, ...] = ()) -> FitResult:
    """A FitResult with the :data:`FITTED` values (as ``clutchlab fit-physics`` writes one)."""
    return synthetic_fit(FITTED, effects)


@lru_cache(maxsize=1)
def fit_json() -> Path:
    """The fitted model as a JSON file."""
    path = TMP / "fitted.json"
    fit_result().to_json(path)
    return path


@lru_cache(maxsize=4)
def exported(drive: str) -> Path:
    """The FMU of the fitted model for ``drive`` (exported once per session, from the JSON)."""
    return export_physics_fmu(fit_json(), TMP / f"fitted_{drive}.fmu", drive=drive)


@lru_cache(maxsize=2)
def medium_trace(waveform: str = "sine"):
    """One medium-ramp stand experiment (23 s at 1 kHz, 50 Hz dither, shape B)."""
    config = StandConfig(
        settings=(DitherSetting(50.0, "B", waveform),), ramps=(RAMPS["medium"],), seed=3
    )
    return run_stand(config, progress=False).dataset[0]


def rewrite(src: Path, dst: Path, xml=None, drop=None) -> Path:
    """A copy of the FMU ``src`` with ``modelDescription.xml`` passed through ``xml(text)``
    and the members for which ``drop(name)`` is true left out."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w") as zout:
        for item in zin.infolist():
            if drop is not None and drop(item.filename):
                continue
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml" and xml is not None:
                data = xml(data.decode("utf-8")).encode("utf-8")
            zout.writestr(item, data)
    return dst


def rename_variable(text: str, old: str, new: str) -> str:
    """``modelDescription.xml`` text with variable ``old`` renamed ``new``."""
    return re.sub(rf'name="{old}"', f'name="{new}"', text)


def input_table(stop_s: float = 0.3, **constant: float) -> np.ndarray:
    """An input table: 0 → 800 mA over ``stop_s``, 100 mA dither at 50 Hz, then the
    ``constant`` inputs (fmpy's format)."""
    t = np.linspace(0.0, stop_s, 31)
    names = ("current_cmd_mA", "dither_amp_mA", "dither_freq_Hz", *constant)
    sig = np.zeros(t.size, dtype=[("time", float), *((n, float) for n in names)])
    sig["time"] = t
    sig["current_cmd_mA"] = 800.0 * t / stop_s
    sig["dither_amp_mA"] = 100.0
    sig["dither_freq_Hz"] = 50.0
    for name, value in constant.items():
        sig[name] = value
    return sig


def simulate_logged(fmu, sig: np.ndarray, start_values=None):
    """Run ``fmu`` at 1 ms steps on the input table ``sig`` (held inputs, linearly
    interpolated at each step's start, as ``fmpy.simulate_fmu``): the clutch pressure at
    the steps' ends (or the exception fmpy raised, naming the FMI call) and the FMU's log
    messages.

    Not ``fmpy.simulate_fmu(logger=...)``: FMPy's logger proxy keeps that logger in one
    process-global slot, and the next FMU logging through FMPy's default callbacks calls
    the freed callback (a segmentation fault in a later test)."""
    from fmpy import calloc, free
    from fmpy.fmi2 import (
        FMU2Slave,
        fmi2CallbackAllocateMemoryTYPE,
        fmi2CallbackFreeMemoryTYPE,
        fmi2CallbackFunctions,
        fmi2CallbackLoggerTYPE,
    )

    md = fmpy.read_model_description(str(fmu))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    messages: list[str] = []

    def logger(env, instance, status, category, message):
        messages.append(message.decode("utf-8", "replace") if message else "")

    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(logger)
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    unzip = fmpy.extract(str(fmu))
    slave = FMU2Slave(
        guid=md.guid, unzipDirectory=unzip, modelIdentifier=md.coSimulation.modelIdentifier
    )
    names = [n for n in sig.dtype.names if n != "time"]
    refs = [vr[n] for n in names]

    def inputs_at(t: float) -> list[float]:
        return [float(np.interp(t, sig["time"], sig[n])) for n in names]

    out: list[float] = []
    try:
        slave.instantiate(callbacks=callbacks)
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        for name, value in (start_values or {}).items():
            slave.setReal([vr[name]], [value])
        slave.setReal(refs, inputs_at(0.0))
        slave.exitInitializationMode()
        for k in range(round(float(sig["time"][-1]) / 1e-3)):
            slave.setReal(refs, inputs_at(k * 1e-3))
            slave.doStep(k * 1e-3, 1e-3)
            out.append(slave.getReal([vr["clutch_pressure_bar"]])[0])
    except Exception as exc:  # FMPy's FMICallException names the FMI call
        return exc, " ".join(messages)
    finally:
        slave.freeInstance()
        shutil.rmtree(unzip, ignore_errors=True)
    return np.array(out), " ".join(messages)
