"""The communication step and the internal step of a physics FMU are separate.

``export-fmu --step`` sets the default experiment's step only; whatever step the master
takes, the FMU integrates in internal steps of at most 1 ms (``max_step_s``, refused above
that at initialization), ``substeps`` ROS2 steps each (1..16, checked before any work).
"""

from __future__ import annotations

import subprocess
import sys

import fmpy
import numpy as np
import pytest
from fmu_support import TMP, exported, fit_json, input_table, simulate_logged

from clutchlab.physics.fmu import FmuError, export_physics_fmu
from clutchlab.physics.fmu import export as export_module

#: The internal step the model is accurate at (s): ``physics.INTERNAL_STEP_S`` (a literal
#: here, so that the test also runs on code without that name).
INTERNAL_STEP_S = 1e-3

#: The stand's line pressure (bar): clutch pressure stays below it (+ sensor overshoot).
LINE_BAR = 17.7


def _ramp(stop_s: float = 4.0) -> np.ndarray:
    """0 → 1100 mA over ``stop_s`` (4 s: through the latch), 100 mA dither at 50 Hz."""
    t = np.linspace(0.0, stop_s, 401)
    names = ("current_cmd_mA", "dither_amp_mA", "dither_freq_Hz")
    sig = np.zeros(t.size, dtype=[("time", float), *((n, float) for n in names)])
    sig["time"] = t
    sig["current_cmd_mA"] = 1100.0 * t / stop_s
    sig["dither_amp_mA"] = 100.0
    sig["dither_freq_Hz"] = 50.0
    return sig


def _pressure(fmu, interval: float, **kw) -> tuple[np.ndarray, np.ndarray]:
    res = fmpy.simulate_fmu(
        str(fmu),
        stop_time=4.0,
        output_interval=interval,
        input=_ramp(),
        output=["clutch_pressure_bar"],
        **kw,
    )
    return res["time"], res["clutch_pressure_bar"]


def _start(fmu, name: str) -> float:
    md = fmpy.read_model_description(str(fmu))
    return float(next(v.start for v in md.modelVariables if v.name == name))


def test_export_step_sets_only_the_default_experiment_and_a_long_step_is_split():
    """``--step 0.01`` used to set ``max_step_s`` (and the settling step) to 10 ms: the
    ramp diverged at t = 1.61 s (``state not finite``); with ``--step 1`` the clutch
    pressure reached 240 bar. Now the 10 ms FMU computes what the default one does."""
    fmu = export_physics_fmu(fit_json(), TMP / "step_10ms.fmu", step_s=0.01)
    md = fmpy.read_model_description(str(fmu))
    assert md.defaultExperiment.stepSize == "0.01"
    assert _start(fmu, "max_step_s") == INTERNAL_STEP_S
    assert _start(fmu, "settle_step_s") == INTERNAL_STEP_S
    t, p = _pressure(fmu, 0.01)  # raised "state not finite" on the old code
    t_ref, p_ref = _pressure(exported("command"), 0.01)
    np.testing.assert_array_equal(t, t_ref)
    assert np.max(np.abs(p - p_ref)) < 1e-9
    assert np.all(np.isfinite(p)) and p.max() < LINE_BAR + 1.0


def test_one_second_communication_steps_stay_physical():
    """A 1 s communication step is split into 1 ms internal steps (the old ``--step 1``
    FMU integrated with 1 s steps: 240 bar)."""
    fmu = export_physics_fmu(fit_json(), TMP / "step_1s.fmu", step_s=1.0)
    _, p = _pressure(fmu, 1.0)
    _, p_ref = _pressure(exported("command"), 1.0)
    assert np.max(np.abs(p - p_ref)) < 1e-9
    assert np.all(np.isfinite(p)) and p.max() < LINE_BAR + 1.0


def test_an_internal_step_above_the_accurate_one_is_refused_at_initialization():
    """``max_step_s`` > 1 ms is refused with a message naming it and the bound; ≤ 0 too
    (it used to switch the splitting off)."""
    fmu = exported("command")
    for bad in (0.01, 0.0, -1e-3):
        # simulate_logged, not fmpy.simulate_fmu(logger=...): FMPy keeps that logger in a
        # process-global slot, and a later FMU in this process would call it freed
        result, text = simulate_logged(fmu, input_table(), start_values={"max_step_s": bad})
        assert isinstance(result, Exception), result
        assert "fmi2ExitInitializationMode" in str(result), result
        assert f"max_step_s = {bad:g} s" in text and "at most 0.001 s" in text, text
    _, p = _pressure(fmu, 0.01, start_values={"max_step_s": 2.5e-4})  # shorter: allowed
    _, p_ref = _pressure(fmu, 0.01)
    assert np.median(np.abs(p - p_ref)) < 0.02  # 3e-3 bar measured (latch snap: 0.26)


@pytest.mark.parametrize("substeps", [-2, 0, 17, 1000, 2.5])
def test_substeps_out_of_range_are_refused_before_any_work(substeps, monkeypatch):
    """``--substeps -2`` built an FMU stuck at 0.5 bar, 0 silently became 4, 1000 ran gcc
    at 5.7 GB for more than 10 minutes; now 1..16 as ``fit-physics --substeps``."""

    def no_work(*args, **kwargs):
        raise AssertionError("the model was read before the options were checked")

    monkeypatch.setattr(export_module, "physics_source", no_work)
    with pytest.raises(FmuError, match=r"substeps must be 1\.\.16"):
        export_physics_fmu(fit_json(), TMP / "never.fmu", substeps=substeps)
    assert not (TMP / "never.fmu").exists()


def test_export_fmu_cli_refuses_substeps_out_of_range(tmp_path):
    out = tmp_path / "s.fmu"
    cmd = [sys.executable, "-m", "clutchlab.cli", "export-fmu", str(fit_json()), "--out"]
    for bad in ("-2", "0", "1000"):
        res = subprocess.run(
            [*cmd, str(out), "--substeps", bad], capture_output=True, text=True, timeout=120
        )
        assert res.returncode == 2, res.stderr
        assert "substeps must be 1..16" in res.stderr and "Traceback" not in res.stderr
        assert not out.exists()
    res = subprocess.run(
        [*cmd, str(out), "--step", "0"], capture_output=True, text=True, timeout=120
    )
    assert res.returncode == 2 and "step must be a positive number" in res.stderr
