"""Shared material of the FMU tests: a "fitted" model, its FMUs (built once per session),
stand traces, and tools to make broken FMUs out of a good one."""

from __future__ import annotations

import re
import tempfile
import zipfile
from functools import lru_cache
from pathlib import Path

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
