"""A design point that breaks the simulation is recorded as failed and the sweep finishes."""

from __future__ import annotations

import numpy as np
import pytest

from clutchlab.physics.design import SweepSpec, read_results, run_sweep
from clutchlab.physics.design.evaluate import DesignEvaluator

#: A corner of the design space where ROS2 at one substep per 1 ms sample diverges:
#: soft oil (β = 0.5 GPa), a heavy, stiff, underdamped VFS armature and spool, a large VFS
#: accumulator. Found by a random search over parameter bounds; with the armature damped
#: (vfs_c = 80 N·s/m) it runs. (At β = 1.25 GPa, this test's good point until the physical
#: range check, it stays finite but the VFS pressure reaches −7 bar where 16 substeps and
#: Radau give ≥ 0.46 bar; such a point is now failed too.)
#: (``python -m clutchlab.cli sweep`` on this spec prints the same failure.)
DIVERGING = {
    "name": "diverging_corner",
    "model": {
        "effects": [
            "oil_temperature",
            "vfs_magnetic_hysteresis",
            "accumulator_spring_nonlinearity",
        ],
        "parameters": {
            "vfs_F_pre": 5.0,
            "vfs_k": 10.0,
            "vfs_m": 30.0,
            "vfs_d_fb": 2.0,
            "vfs_w": 10.0,
            "vfs_G_leak": 1.0,
            "vacc_d": 30.0,
            "reg_d_pil": 20.0,
            "reg_m": 60.0,
            "accnl_kappa_c": 2.0,
            "fluid_beta": 0.5,
        },
    },
    "scenario": {"ramps": [{"label": "short", "ramp_s": 0.6, "hold_s": 0.2}], "step": False},
    "simulation": {"substeps": 1},
    "sampling": {"method": "grid"},
    "variables": [{"name": "vfs_c", "values": [1.0, 80.0]}],
}


def test_diverging_point_is_recorded_with_its_message_and_the_sweep_finishes(tmp_path):
    spec = SweepSpec.from_dict(DIVERGING)
    out = tmp_path / "corner.parquet"
    res = run_sweep(spec, out, workers=1, progress=False)
    df = read_results(out)
    assert len(df) == 2 and res.n_failed == 1
    bad = df[df["vfs_c"] == 1.0].iloc[0]
    good = df[df["vfs_c"] == 80.0].iloc[0]
    assert bad["status"] == "failed"
    assert bad["error"].startswith("SimulationError: state not finite at t = ")
    assert "the integrator diverged for these parameters" in bad["error"]
    assert np.isnan(bad["regulated_gain_bar_per_A"]) and np.isnan(bad["ripple_rms_bar"])
    assert good["status"] == "ok" and good["error"] == ""
    assert np.isfinite(good["ripple_rms_bar"])
    assert res.summary()["failures"] == [{"point_id": bad["point_id"], "error": bad["error"]}]
    assert all(f.exists() for f in res.figures)  # figures are drawn with a failed point
    # A restart counts the failed point as done; --retry-failed runs it again (fails again).
    assert run_sweep(spec, out, workers=1, progress=False, figures=False).n_run == 0
    again = run_sweep(spec, out, workers=1, progress=False, figures=False, retry_failed=True)
    assert again.n_run == 1 and again.n_failed == 1 and len(again.table) == 2


def test_any_exception_in_a_point_is_recorded_not_raised(tmp_path, monkeypatch):
    spec = SweepSpec.from_dict(
        {
            "scenario": {
                "ramps": [{"label": "short", "ramp_s": 0.6, "hold_s": 0.2}],
                "step": False,
            },
            "simulation": {"settle_s": 0.2},
            "sampling": {"method": "grid"},
            "variables": [{"name": "reg_k", "values": [10.0, 13.0, 20.0]}],
        }
    )
    original = DesignEvaluator._metrics

    def flaky(self, values):
        if values["reg_k"] == 13.0:
            raise ZeroDivisionError("division by zero in a user metric")
        return original(self, values)

    monkeypatch.setattr(DesignEvaluator, "_metrics", flaky)
    res = run_sweep(spec, tmp_path / "r.parquet", workers=1, progress=False, figures=False)
    df = res.table
    assert list(df["status"]) == ["ok", "failed", "ok"]
    assert df.loc[1, "error"].startswith("ZeroDivisionError: division by zero in a user metric")
    assert "[flaky:" in df.loc[1, "error"]  # where it was raised


@pytest.mark.slow
def test_diverging_point_in_a_worker_process_is_recorded(tmp_path):
    spec = SweepSpec.from_dict(DIVERGING)
    res = run_sweep(spec, tmp_path / "c.parquet", workers=2, progress=False, figures=False)
    assert sorted(res.table["status"]) == ["failed", "ok"]
    assert "SimulationError" in res.table.loc[res.table["status"] == "failed", "error"].iloc[0]


#: A design inside every parameter's bounds (from a random search over them) whose fast
#: ramp at the default 4 substeps stays finite but is wrong by far more than the
#: integration tolerance: pressures of −10 bar to ±10⁴ bar (at 16 substeps the same design
#: stays within 0–17.7 bar). It used to be stored as ``ok`` with metrics of that garbage.
UNRESOLVED = {
    "fluid_rho": 879.142, "fluid_Cd": 0.663, "fluid_p_cr": 0.672, "vfs_K_m": 9.91,
    "vfs_F_pre": 2.124, "vfs_c": 1.463, "vfs_F_c": 0.327, "vfs_v_s": 0.441, "vfs_d_fb": 2.733,
    "vacc_d": 22.868, "vacc_p0": 4.387, "vacc_stroke": 23.582, "reg_d_fb": 15.523,
    "reg_m": 32.514, "reg_k": 6.441, "reg_F0": 8.063, "reg_F_c": 0.347, "latch_d1": 3.556,
    "latch_d2": 9.035, "latch_F0": 66.783, "latch_k": 0.241, "latch_stroke": 1.854,
    "latch_F_w": 0.356, "latch_tau": 49.316, "cacc_d": 17.892, "cacc_k": 12.054,
    "cacc_p0": 0.363,
}  # fmt: skip


def test_a_finite_but_unphysical_point_is_failed_not_ok():
    from clutchlab.physics.design.sampling import design_points

    spec = SweepSpec.from_dict(
        {
            "model": {"parameters": UNRESOLVED},
            "scenario": {"ramps": ["fast"], "step": False},
            "sampling": {"method": "grid"},
            "variables": [{"name": "vfs_d_orf", "values": [0.6]}],
        }
    )
    (row,) = [DesignEvaluator(spec).evaluate(p) for p in design_points(spec)]
    assert row["status"] == "failed"
    assert row["error"].startswith("SimulationError: ramp_fast: ")
    assert "outside the range the circuit can reach [-1, 26.55] bar" in row["error"]
    assert "raise substeps" in row["error"]
    assert np.isnan(row["latch_on_mA"]) and np.isnan(row["hysteresis_fast_bar"])
