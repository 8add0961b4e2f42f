"""The hybrid's form (residual on the physics, or standalone) chosen inside the training set."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from clutchlab.data import dither_period_mean, dither_period_samples
from clutchlab.errors import ModelError
from clutchlab.residual_ml import HybridModel, SVCPartitionedGP, load_model, save_model
from clutchlab.residual_ml.physics import PhysicsPredictor


class _Recording:
    """A physics model that explains nothing (smoothed noise of 2 bar, seeded by the trace's
    name) and records the traces it saw."""

    def __init__(self):
        self.seen: list[str] = []

    def predict(self, trace):
        self.seen.append(trace.name)
        rng = np.random.default_rng(sum(trace.name.encode()))
        noise = rng.standard_normal(len(trace)) * 2.0
        return 8.0 + np.convolve(noise, np.ones(300) / np.sqrt(300), mode="same")


def _rmse(model, traces):
    e = []
    for t in traces:
        n = dither_period_samples(t)
        e.append(
            dither_period_mean(model.predict(t), n)
            - dither_period_mean(t.get("clutch_pressure_bar"), n)
        )
    return float(np.sqrt(np.mean(np.concatenate(e) ** 2)))


@pytest.fixture(scope="module")
def split(stand_run):
    ds = stand_run.dataset
    return list(ds.select(ramps=["fast", "slow"])), list(ds.select(ramps=["medium"]))


@pytest.fixture(scope="module")
def truth_physics(stand_run):
    return PhysicsPredictor(
        effects=tuple(stand_run.model.effect_names), params=dict(stand_run.params.values)
    )


@pytest.fixture(scope="module")
def auto_truth(split, truth_physics):
    """The hybrid on the stand's own truth model, its form chosen on forked workers (shared:
    each such fit runs twelve fold fits)."""
    train, _ = split
    return HybridModel(physics=truth_physics, standalone_handicap="auto").fit(train)


def test_wrong_physics_gives_the_standalone_form_and_never_sees_the_test_ramp(split):
    train, test = split
    phys = _Recording()
    model = HybridModel(physics=phys, standalone_handicap="auto").fit(train)
    assert model.form_ == "standalone"
    assert set(model.form_scores_) == {"residual", "standalone", "physics"}
    assert model.form_scores_["standalone"] < model.form_scores_["residual"]
    # The choice saw training traces only, and training inputs played faster (the handicap's
    # probe: "slow_50Hz_B_x4" from "slow_50Hz_B"), never a test trace.
    names = {t.name for t in train}
    assert all(n in names or n.rsplit("_x", 1)[0] in names for n in phys.seen)
    assert any(n not in names for n in phys.seen)  # the probe ran
    assert not set(phys.seen) & {t.name for t in test}
    # Standalone = the paper pipeline on the same training traces.
    paper = SVCPartitionedGP().fit(train)
    assert _rmse(model, test) == pytest.approx(_rmse(paper, test), rel=1e-6)


def test_exact_physics_gives_the_physics_form(auto_truth):
    """The stand's own truth model: nothing is left for a residual model to learn."""
    model = auto_truth
    assert model.form_ == "physics"
    assert model.form_scores_["physics"] < 0.05 < model.form_scores_["standalone"]


def test_the_form_scores_are_the_same_on_worker_processes(
    split, truth_physics, auto_truth, monkeypatch
):
    """The folds' fits run on forked workers; in this process they give the same numbers."""
    import clutchlab.residual_ml.hybrid as hybrid_module

    train, _ = split
    forked = auto_truth.form_scores_
    monkeypatch.setattr(hybrid_module, "default_workers", lambda: 1)
    here = HybridModel(physics=truth_physics, standalone_handicap="auto").fit(train)
    assert forked == here.form_scores_
    assert auto_truth.standalone_handicap_ == here.standalone_handicap_


def test_datasheet_physics_gives_the_residual_form(split):
    """Right structure, wrong parameters (0.3 bar off): the residual model corrects it."""
    train, test = split
    physics = PhysicsPredictor()
    model = HybridModel(physics=physics).fit(train)
    assert model.form_ == "residual"
    assert model.form_scores_["residual"] < min(
        model.form_scores_["standalone"], model.form_scores_["physics"]
    )
    fixed = HybridModel(physics=physics, form="residual").fit(train)
    assert _rmse(model, test) == pytest.approx(_rmse(fixed, test), rel=1e-9)
    assert fixed.form_scores_ == {}


def test_form_round_trips_and_a_bad_form_is_refused(split, tmp_path):
    train, test = split
    model = HybridModel(physics=_Recording(), form="standalone").fit(train)
    with pytest.raises(ModelError):
        HybridModel(physics=_Recording(), form="both").fit(train)
    path = tmp_path / "h.json"
    fitted = HybridModel(physics=PhysicsPredictor(), form="standalone", standalone_handicap=2.0)
    save_model(fitted.fit(train), path)
    loaded = load_model(path)
    assert loaded.form_ == "standalone" and loaded.standalone_handicap == 2.0
    assert np.isnan(loaded.standalone_handicap_)  # the form was given: no handicap used
    np.testing.assert_allclose(loaded.predict(test[0]), model.predict(test[0]), atol=1e-9)


def test_physics_form_predicts_the_physics_with_its_loeo_error_as_std(
    split, truth_physics, auto_truth
):
    train, test = split
    model = HybridModel(physics=truth_physics, form="physics").fit(train)
    trace = test[0]
    np.testing.assert_array_equal(model.predict(trace), truth_physics.predict(trace))
    comp = model.predict_components(trace)
    assert np.all(comp["residual_bar"] == 0)
    auto = copy.copy(auto_truth)  # its form is set below: the shared fit stays as it was
    assert set(auto.form_scores_) == {"residual", "standalone", "physics"}
    auto.form_ = "physics"  # as if chosen: its std is the physics form's LOEO RMSE
    _, std = auto.predict(trace, return_std=True)
    assert np.all(std == auto.form_scores_["physics"])
    # Asked for by name, the physics form scores itself the same way: a finite std, not NaN.
    assert set(model.form_scores_) == {"physics"}
    assert model.form_scores_["physics"] == pytest.approx(auto.form_scores_["physics"], rel=1e-12)
    _, std = model.predict(trace, return_std=True)
    assert np.all(std == model.form_scores_["physics"]) and np.all(np.isfinite(std))


def test_the_residual_forms_latch_decision_is_a_choice_with_the_classifier_as_default(
    split, truth_physics
):
    from clutchlab.residual_ml.hybrid import RESIDUAL_LATCH_MODEL, default_residual

    assert RESIDUAL_LATCH_MODEL == "classifier"
    assert default_residual().latch_model == "classifier"
    train, _ = split
    res = default_residual("local_event")
    model = HybridModel(physics=truth_physics, residual=res, form="residual").fit(train)
    assert model.residual_.latch_model_ == "local_event"
    # the standalone form of the default residual keeps its own (local) latch law
    alone = HybridModel(physics=truth_physics, form="standalone").fit(train)
    assert alone.residual_.latch_model_ == "local_event"


def test_the_standalone_handicap_decides_between_loeo_scores_and_is_checked():
    from clutchlab.residual_ml.hybrid import STANDALONE_HANDICAP

    scores = {"residual": 0.20, "standalone": 0.40, "physics": 0.50}
    assert STANDALONE_HANDICAP == 3.0 and HybridModel().standalone_handicap == 3.0
    assert HybridModel()._choose_form(scores) == "standalone"  # 0.40 / 3 < 0.20
    assert HybridModel(standalone_handicap=1.0)._choose_form(scores) == "residual"
    assert HybridModel()._choose_form({"residual": 0.03, "standalone": 0.3}) == "residual"
    for bad in (0.0, -1.0, float("nan"), "abc", None):
        with pytest.raises(ModelError, match="standalone_handicap"):
            HybridModel(standalone_handicap=bad)._choose_form(scores)
    # "auto" takes the handicap measured on the physics' data; a number wins
    assert HybridModel(standalone_handicap="auto")._choose_form(scores, 1.0) == "residual"
    assert HybridModel(standalone_handicap="auto")._choose_form(scores) == "standalone"
    assert HybridModel(standalone_handicap=3.0)._choose_form(scores, 1.0) == "standalone"


def test_the_measured_handicap_is_the_probe_folds_over_the_between_rate_error():
    measured = HybridModel._measured_handicap
    assert measured({"probe_folds": [np.full(9, 0.6)], "probe_between": [np.full(4, 0.1)]}) == (
        pytest.approx(6.0)
    )
    assert measured({"probe_folds": [np.full(9, 0.1)], "probe_between": [np.full(4, 0.2)]}) == 1.0
    assert measured({"probe_folds": [np.ones(9)], "probe_between": [np.zeros(4)]}) is None
    assert measured({"residual": [np.ones(9)]}) is None  # no probe: the constant


def test_the_hybrid_measures_its_handicap_on_the_physics_data(
    split, truth_physics, auto_truth, tmp_path
):
    from clutchlab.residual_ml.hybrid import STANDALONE_HANDICAP

    train, _ = split
    kappa = auto_truth.standalone_handicap_
    assert np.isfinite(kappa) and kappa >= 1.0 and kappa != STANDALONE_HANDICAP
    save_model(auto_truth, tmp_path / "auto.json")
    assert load_model(tmp_path / "auto.json").standalone_handicap_ == kappa
    model = HybridModel(physics=truth_physics)
    outputs = [model._outputs(truth_physics, t) for t in train]
    syn, between = model._probe_traces(truth_physics, train, outputs)
    slow = [t.name for t in train if t.ramp == "slow"]
    assert sorted(t.name for t in between) == sorted(f"{n}_x4" for n in slow)
    for t, (raw, _) in zip(syn, outputs, strict=True):
        np.testing.assert_array_equal(t.get("clutch_pressure_bar"), raw)
    np.testing.assert_allclose(
        between[0].get("clutch_pressure_bar"), truth_physics.predict(between[0]), rtol=1e-9
    )
    fast = [i for i, t in enumerate(train) if t.ramp == "fast"]  # one rate: nothing between
    one_rate = [train[i] for i in fast], [outputs[i] for i in fast]
    assert model._probe_traces(truth_physics, *one_rate) is None
