"""The exported predictive standard deviation: the in-process std, from the coarse std bins."""

from __future__ import annotations

import numpy as np
import pytest
from fmu_support import TMP, medium_trace
from test_fmu_ml import gp_std, synthetic_gp

from clutchlab.errors import ModelError
from clutchlab.physics.fmu import FmuPhysics, build_fmu
from clutchlab.physics.fmu.adapters import gp_spec, ml_program_from
from clutchlab.physics.fmu.ml import GPSpec, ml_program
from clutchlab.residual_ml import GPBaseline, LocalGPRegressor

BASE = ("current_mA", "dither_amp_mA", "dither_freq_Hz")
SIGNALS = ("current_cmd_mA", "dither_amp_mA", "dither_freq_Hz")


def _inputs(trace) -> np.ndarray:
    return np.column_stack([trace.get(n) for n in SIGNALS])


def test_fmu_std_on_coarse_std_bins_equals_the_in_process_std():
    """A GP whose std bins are coarser than its mean bins: the FMU evaluates both from the
    same arrays as ``predict`` and gives the same mean and std at every sample."""
    X = _inputs(medium_trace("triangle"))
    y = medium_trace("triangle").get("clutch_pressure_bar")
    gp = LocalGPRegressor(kernel="rbf", max_points=400, n_hyper=300, max_std_points=40)
    gp.fit(X, y)
    assert gp.n_std_bins_ <= 40 < gp.n_bins_
    spec = gp_spec(gp)
    assert spec.std_points.shape[0] == gp.n_std_bins_
    fmu = build_fmu(ml_program(spec, BASE, name="gp_coarse_std"), TMP / "gp_coarse_std.fmu")
    trace = medium_trace()
    sim = FmuPhysics(fmu).simulate(trace)
    mean, std = gp.predict(_inputs(trace), return_std=True)
    assert np.abs(sim.pressure_bar - mean).max() < 1e-9
    assert np.abs(sim.outputs["clutch_pressure_std_bar"] - std).max() < 1e-8
    # the std bins matter: the std on the mean's bins differs from what the FMU outputs
    fine = gp_spec(LocalGPRegressor().set_state(*_without_std_bins(gp)))
    assert fine.std_points.shape[0] == gp.n_bins_
    assert np.abs(gp_std(fine, _inputs(trace)) - std).max() > 1e-5


def _without_std_bins(gp: LocalGPRegressor):
    meta, arrays = gp.get_state()
    return meta, {k: v for k, v in arrays.items() if "std" not in k}


def test_estimator_std_matches_in_process():
    est = GPBaseline(max_points=300, n_hyper=300).fit([medium_trace("triangle")])
    fmu = build_fmu(ml_program_from(est, name="gp_std"), TMP / "gp_std.fmu")
    trace = medium_trace()
    sim = FmuPhysics(fmu).simulate(trace)
    est.set_params(knot_tol=0.0)
    mean, std = est.predict(trace, return_std=True)
    assert np.abs(sim.pressure_bar - mean).max() < 1e-6
    assert np.abs(sim.outputs["clutch_pressure_std_bar"] - std).max() < 1e-8


def test_std_arrays_are_checked():
    spec = synthetic_gp(5, 3, n=30, n_std=10)
    fields = dict(spec.__dict__)
    with pytest.raises(ModelError, match=r"l_inv must have shape \(10, 10\)"):
        GPSpec(**{**fields, "l_inv": np.eye(30)})
    with pytest.raises(ModelError, match=r"std_points must have shape \(m, 3\)"):
        GPSpec(**{**fields, "std_points": np.zeros((10, 2))})
    with pytest.raises(ModelError, match="with_std needs l_inv"):
        ml_program(GPSpec(**{**fields, "l_inv": None}), BASE)


def test_std_terms_the_fmu_omits_are_named_and_the_rest_is_exact(tmp_path, capsys):
    """Trained on two experiments, a GP's std has a leave-one-experiment-out variance floor
    the FMU does not compute: it is named (by the export CLI too) and the FMU's std is the
    smaller one; with the GP's own std (``mean_only``) nothing is omitted and the FMU's std
    is the in-process one."""
    from clutchlab.cli import main
    from clutchlab.physics.fmu.adapters import std_terms_not_exported
    from clutchlab.physics.stand import DitherSetting, StandConfig, run_stand
    from clutchlab.physics.stand.scenarios import RampProfile
    from clutchlab.residual_ml import mean_only, save_model

    config = StandConfig(
        settings=(DitherSetting(50.0, "B"),),
        ramps=(RampProfile("fast", 2.5), RampProfile("slow", 8.0)),
        seed=5,
    )
    train = list(run_stand(config, progress=False).dataset)
    trace = medium_trace()
    full = GPBaseline(max_points=300, n_hyper=300).fit(train)
    own = mean_only(GPBaseline(max_points=300, n_hyper=300)).fit(train)
    assert std_terms_not_exported(full) == [
        "leave-one-experiment-out residual-variance floor (residual_variance)"
    ]
    assert std_terms_not_exported(own) == []
    for est, name in ((full, "gp_full"), (own, "gp_own")):
        fmu = build_fmu(ml_program_from(est, name=name), TMP / f"{name}.fmu")
        sim = FmuPhysics(fmu).simulate(trace)
        est.set_params(knot_tol=0.0)
        mean, std = est.predict(trace, return_std=True)
        gap = std - sim.outputs["clutch_pressure_std_bar"]
        assert np.abs(sim.pressure_bar - mean).max() < 1e-6
        if est is own:
            assert np.abs(gap).max() < 1e-8
        else:
            assert gap.min() > -1e-8 and gap.max() > 1e-4  # the floor only ever adds
    path = tmp_path / "gp_full.json"
    save_model(full, path)
    assert main(["export-fmu", str(path), "--out", str(tmp_path / "gp_full.fmu")]) == 0
    assert "residual-variance floor" in capsys.readouterr().out
