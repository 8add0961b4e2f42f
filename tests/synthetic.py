"""Synthetic traces with known inputs for the tests."""

from __future__ import annotations

import numpy as np

from clutchlab.data import Trace


def make_trace(
    knots_t,
    knots_mA,
    *,
    dt=1e-3,
    dither_mA=100.0,
    dither_Hz=50.0,
    temp_C=40.0,
    line_bar=17.7,
    name="synthetic",
    ramp="fast",
) -> Trace:
    """A command-only trace: piecewise-linear nominal current, constant dither/line/temp."""
    t = np.arange(knots_t[0], knots_t[-1] + 0.5 * dt, dt)
    n = len(t)
    signals = {
        "time_s": t,
        "current_cmd_mA": np.interp(t, knots_t, knots_mA),
        "dither_amp_mA": np.full(n, float(dither_mA)),
        "dither_freq_Hz": np.full(n, float(dither_Hz)),
        "clutch_pressure_bar": np.zeros(n),
        "line_pressure_bar": np.full(n, float(line_bar)),
        "oil_temp_C": np.full(n, float(temp_C)),
    }
    return Trace(name, signals, meta={"ramp": ramp})


def _tiny_ramps():
    """The tiny datasets' ramps: fast / medium / slow, 1 / 2 / 4 s, 0.3 s holds."""
    from clutchlab.physics.stand import RampProfile

    return tuple(RampProfile(n, d, 0.3) for n, d in (("fast", 1.0), ("medium", 2.0), ("slow", 4.0)))


def tiny_stand(seed: int):
    """Six short stand experiments: fast / medium / slow (1 / 2 / 4 s ramps) × (30 Hz A,
    70 Hz B), two substeps; the dataset of the ML tests (seed of noise and wander)."""
    from clutchlab.physics.stand import DitherSetting, StandConfig, run_stand

    config = StandConfig(
        settings=(DitherSetting(30.0, "A"), DitherSetting(70.0, "B")),
        ramps=_tiny_ramps(),
        substeps=2,
        seed=seed,
    )
    return run_stand(config, progress=False).dataset


def tiny_zoo(plant: str, seed: int, settings: tuple[tuple[float, str], ...]):
    """Short experiments of a zoo plant: fast / medium / slow (1 / 2 / 4 s ramps) × the
    dither ``settings`` ((frequency Hz, amplitude label), ...), two substeps (seed of the
    unit, noise and wander)."""
    from clutchlab.physics.stand import DitherSetting
    from clutchlab.physics.stand.plants.run import PlantConfig, run_plant

    config = PlantConfig(
        plant,
        settings=tuple(DitherSetting(f, a) for f, a in settings),
        ramps=_tiny_ramps(),
        substeps=2,
        seed=seed,
    )
    return run_plant(config, progress=False).dataset


def tiny_supply_coupled(seed: int):
    """Fifteen short experiments of ``stribeck_supply``, whose latch switches move with
    line pressure (five dither settings, :func:`tiny_zoo`)."""
    settings = ((30.0, "A"), (70.0, "B"), (50.0, "C"), (30.0, "C"), (70.0, "A"))
    return tiny_zoo("stribeck_supply", seed, settings)


def tiny_never_latching(seed: int = 2):
    """Fifteen short experiments of ``quadratic_play`` seed 2, whose 30 Hz B setting never
    latches up to its 1100 mA peak (:func:`tiny_zoo`)."""
    settings = ((30.0, "A"), (30.0, "B"), (70.0, "B"), (50.0, "C"), (70.0, "A"))
    return tiny_zoo("quadratic_play", seed, settings)


def check_latch_law_model(model, data, tmp_path, kind: str) -> None:
    """A partitioned GP whose latch law is ``kind``: it latches and releases on an unseen
    ramp, survives save / load, and its step predictor equals the batch path."""
    from clutchlab.residual_ml import load_model, step_predictor

    assert model.latch_model_ == kind and model.classifier_ is None
    assert model.classifier_train_accuracy_ > 0.99
    tr = data["medium_30Hz_A"]
    latch = model.predict_latch(tr)
    assert 0 < latch.mean() < 1  # it latches and releases on the unseen ramp
    model.save(tmp_path / "m.json")
    back = load_model(tmp_path / "m.json")
    assert back.latch_model_ == kind
    np.testing.assert_array_equal(back.predict(tr), model.predict(tr))
    step = step_predictor(model)
    F = model._trace_matrix(tr)[::53]
    line = tr.get("line_pressure_bar")[::53]
    exact = model._predict_matrix(F, path=False, return_std=False, ref=line)
    got = np.array([step(x, line_bar=v) for x, v in zip(F, line, strict=True)])
    np.testing.assert_allclose(got, exact, atol=1e-9)


def check_latch_law_fmu(data, tmp_path, kind: str, **small) -> None:
    """A causal partitioned GP with latch law ``kind`` exports to an FMU whose latch state
    equals the model's and whose pressure is within 0.01 bar of it."""
    from clutchlab.physics.fmu import FmuPhysics, build_fmu, ml_program_from
    from clutchlab.physics.fmu.adapters import decision_spec
    from clutchlab.residual_ml import SVCPartitionedGP
    from clutchlab.residual_ml.features import causal_features

    train = data.select(ramps=["fast", "slow"])
    features = causal_features(SVCPartitionedGP()._builder().names)
    model = SVCPartitionedGP(features=features, latch_model=kind, **small).fit(train)
    spec = decision_spec(model.decision_, model.classifier_columns_)
    assert spec.kind == kind
    assert (spec.event_line is not None) == getattr(model.decision_, "uses_line", False)
    fmu = build_fmu(ml_program_from(model, with_std=False), tmp_path / f"{kind}.fmu")
    model.set_params(knot_tol=0.0)
    tr = data["medium_70Hz_B"]
    sim = FmuPhysics(fmu).simulate(tr)
    np.testing.assert_array_equal(sim.outputs["latch_state"], model.predict_latch(tr))
    assert np.abs(sim.pressure_bar - model.predict(tr)).max() < 0.01
    return model
