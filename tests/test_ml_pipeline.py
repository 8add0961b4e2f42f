"""Paper pipeline on a tiny stand dataset: features, labels, estimators, persistence, steps."""

from __future__ import annotations

import json

import numpy as np
import pytest
from sklearn.base import clone
from sklearn.exceptions import NotFittedError
from synthetic import tiny_stand

from clutchlab.data import Trace, dither_period_mean, dither_period_samples
from clutchlab.errors import DataError, ModelError, OutputError
from clutchlab.residual_ml import (
    EVENT,
    LATCHED,
    UNLATCHED,
    VARIANTS,
    FeatureBuilder,
    GPBaseline,
    GPWithDerivative,
    HybridModel,
    LatchLabelRule,
    PhysicsPredictor,
    SVCPartitionedGP,
    compare_classifiers,
    direction_of_travel,
    latch_labels,
    load_model,
    make_variant,
    save_model,
    score_traces,
    step_predictor,
)
from clutchlab.residual_ml.hybrid import HYBRID_FEATURES

#: Small GPs: the fast tests check behaviour, not accuracy.
SMALL = {"n_hyper": 300, "max_points": 300}


@pytest.fixture(scope="module")
def tiny():
    """Six short stand experiments: fast / medium / slow × (30 Hz A, 70 Hz B)."""
    return tiny_stand(1)


@pytest.fixture(scope="module")
def train(tiny):
    return tiny.select(ramps=["fast", "slow"])


@pytest.fixture(scope="module")
def fitted(train):
    return {
        "gp_base": GPBaseline(**SMALL).fit(train),
        "gp_didt": GPWithDerivative(**SMALL).fit(train),
        "paper_svc_gp": SVCPartitionedGP(**SMALL).fit(train),
        "paper_faithful": make_variant("paper_faithful", **SMALL).fit(train),
        "hybrid": HybridModel(
            physics=PhysicsPredictor(substeps=2),
            residual=SVCPartitionedGP(features=HYBRID_FEATURES, **SMALL),
            form="residual",  # the residual form under test (the form choice: test_hybrid_form)
        ).fit(train),
    }


# -- features and labels ----------------------------------------------------------------------


def test_features_have_units_and_follow_the_trace(tiny):
    tr = tiny["fast_30Hz_A"]
    fb = FeatureBuilder()
    F = fb.build(tr)
    assert F.shape == (len(tr), 5) and fb.units == ("mA", "mA", "Hz", "mA/s", "1")
    np.testing.assert_array_equal(F[:, 0], tr.get("current_cmd_mA"))
    up = (tr.time_s > 0.5) & (tr.time_s < 1.1)
    assert np.allclose(F[up, 3], 1100.0 / 1.0, rtol=0.02)  # 1100 mA in 1 s
    assert (F[up, 4] == 1).all() and F[-1, 4] == -1  # held through the final hold
    with pytest.raises(DataError, match="physics"):
        FeatureBuilder(HYBRID_FEATURES).build(tr)
    with pytest.raises(DataError, match="unknown"):
        FeatureBuilder(("current_mA", "nope"))


def test_features_from_measured_current_only(tiny):
    tr = tiny["slow_30Hz_A"]
    bare = Trace(
        "bare",
        {
            k: v
            for k, v in tr.signals.items()
            if k not in ("current_cmd_mA", "dither_amp_mA", "dither_freq_Hz")
        },
        meta=tr.meta,
    )
    F, G = FeatureBuilder().build(tr), FeatureBuilder().build(bare)
    mid = slice(len(tr) // 10, -len(tr) // 10)
    assert np.median(np.abs(F[mid, 0] - G[mid, 0])) < 5.0  # demodulated current, mA
    assert np.median(np.abs(F[mid, 2] - G[mid, 2])) < 1.0  # frequency, Hz
    assert np.mean(F[mid, 4] == G[mid, 4]) > 0.95  # direction of travel


def test_direction_of_travel_holds_through_dead_band():
    d = np.array([0, 0, 50, 50, 2, 0, -3, -40, 0, 0.0])
    np.testing.assert_array_equal(direction_of_travel(d, 10.0), [0, 0, 1, 1, 1, 1, 1, -1, -1, -1])


def test_latch_labels_rule(tiny):
    tr = tiny["fast_70Hz_B"]
    lab, state = latch_labels(tr, return_state=True)
    p, line = tr.get("clutch_pressure_bar"), tr.get("line_pressure_bar")
    assert set(np.unique(lab)) == {EVENT, UNLATCHED, LATCHED}
    assert np.all(line[lab == LATCHED] - p[lab == LATCHED] < 1.5)
    assert np.all(line[lab == UNLATCHED] - p[lab == UNLATCHED] > 0.5)
    switches = np.flatnonzero(np.diff(state) != 0)
    assert switches.size == 2  # latch on, latch off: no flicker
    for k in switches:
        assert lab[k] == EVENT or lab[k + 1] == EVENT  # every switch sits in a latch event
    assert (lab == EVENT).sum() < 0.05 * len(tr)
    none = latch_labels(tr, LatchLabelRule(event_band_bar=(1.0, 1.0)))
    assert EVENT not in none
    with pytest.raises(DataError, match="margin"):
        LatchLabelRule(margin_bar=3.0, event_band_bar=(0.3, 2.0))


# -- estimators: the scikit-learn contract ---------------------------------------------------


@pytest.mark.parametrize("name", list(VARIANTS))
def test_estimator_contract(name, train, tiny):
    est = make_variant(name)
    with pytest.raises(NotFittedError):
        est.predict(tiny[0])
    c = clone(est)
    assert c.get_params().keys() == est.get_params().keys()
    assert not [k for k in vars(c) if k.endswith("_")]  # __init__ stores arguments only
    with pytest.raises(DataError):
        est.fit(train, y=np.zeros(3))


def _unfitted(name):
    params = {"physics": PhysicsPredictor(substeps=2)} if name == "hybrid" else {}
    return make_variant(name, **params)


@pytest.mark.parametrize("name", list(VARIANTS))
def test_fit_without_experiments_says_so(name, tiny):
    """``fit([])`` raised scikit-learn's "requires y to be passed" (the empty list was taken
    for a feature matrix, so the "no experiments" DataError was never reached)."""
    for empty in ([], (), tiny.select(names=[])):
        with pytest.raises(DataError, match="no training experiments"):
            _unfitted(name).fit(empty)


@pytest.mark.parametrize("name", list(VARIANTS))
def test_fit_on_nan_names_the_experiment_signal_and_row(name, tiny):
    """A NaN clutch pressure raised "x has a non-finite value at row 2", naming neither the
    experiment nor the signal. Now one DataError lists every experiment and signal with a
    non-finite value and its first row, before any fit or physics simulation."""
    fast, slow = tiny.select(ramps=["fast"]), tiny.select(ramps=["slow"])
    p = fast[0].get("clutch_pressure_bar").copy()
    p[[1, 7]] = np.nan
    i = slow[0].get("current_mA").copy()
    i[99] = np.inf
    bad = [fast[0].with_signals(clutch_pressure_bar=p), slow[0].with_signals(current_mA=i)]
    with pytest.raises(DataError) as info:
        _unfitted(name).fit([*bad, fast[1]])
    assert info.value.problems == [
        f"experiment {fast[0].name!r}: clutch_pressure_bar has 2 non-finite value(s), the "
        "first at row 2 (t = 0.001 s)",
        f"experiment {slow[0].name!r}: current_mA has 1 non-finite value(s), the first at "
        "row 100 (t = 0.099 s)",
    ]


@pytest.mark.parametrize("name", list(VARIANTS))
def test_fitted_models_predict_every_sample(name, fitted, tiny):
    model = fitted[name]
    assert model.train_experiments_ == ["fast_30Hz_A", "fast_70Hz_B", "slow_30Hz_A", "slow_70Hz_B"]
    tr = tiny["medium_30Hz_A"]
    mean, std = model.predict(tr, return_std=True)
    assert mean.shape == std.shape == (len(tr),) and np.isfinite(mean).all()
    assert (std >= 0).all()
    many = model.predict(tiny.select(ramps=["medium"]))
    assert isinstance(many, list) and len(many) == 2
    np.testing.assert_array_equal(many[0], mean)


def test_fit_returns_self_and_ablation_on_training_data(train, fitted):
    est = GPBaseline(n_hyper=50, max_points=50)
    assert est.fit(train[:1]) is est
    base = score_traces(fitted["gp_base"], train)["overall"]["rmse_bar"]
    didt = score_traces(fitted["gp_didt"], train)["overall"]["rmse_bar"]
    assert didt < base  # dI/dt explains the hysteresis the baseline cannot


def test_path_prediction_matches_exact_evaluation(fitted, tiny):
    model = fitted["paper_svc_gp"]
    tr = tiny["medium_70Hz_B"]
    F = model._trace_matrix(tr)
    exact = model._predict_matrix(F, path=False, return_std=False, ref=model._trace_ref(tr))
    fast = model.predict(tr)
    n = dither_period_samples(tr)  # knots: interpolation error of the scored signal, bar
    diff = np.abs(dither_period_mean(fast, n) - dither_period_mean(exact, n))
    assert diff.max() < 0.05 and np.mean(diff < 0.01) > 0.98
    every = clone(model).set_params(knot_tol=0.0)
    every.__dict__.update({k: v for k, v in vars(model).items() if k.endswith("_")})
    np.testing.assert_allclose(every.predict(tr), exact, atol=1e-12)  # tol 0: every sample


def test_partitioned_model_classifies_latch(fitted, tiny):
    model = fitted["paper_svc_gp"]
    assert set(model.gps_) == {0, 1}
    assert model.classifier_train_accuracy_ > 0.98
    tr = tiny["fast_30Hz_A"]
    lab = latch_labels(tr)
    pred = model.predict_latch(tr)
    assert np.mean(pred[lab >= 0] == lab[lab >= 0]) > 0.98


def test_hybrid_adds_physics_and_residual(fitted, tiny):
    """The hybrid is physics + residual, and the residual model corrects the physics where
    it was trained. (On this tiny data set with 300-bin GPs the medium ramp is no accuracy
    check: the hybrid's gain on the unseen ramp is tested on the full stand in
    tests/test_ml_slow.py.)"""
    from clutchlab.data import pressure_metrics

    model = fitted["hybrid"]
    parts = model.predict_components(tiny["medium_30Hz_A"])
    np.testing.assert_allclose(parts["pressure_bar"], parts["physics_bar"] + parts["residual_bar"])
    train = tiny.select(ramps=["fast", "slow"])
    rm = score_traces(model, train)["overall"]["rmse_bar"]
    phys = PhysicsPredictor(substeps=2)
    ys, ps = [], []
    for tr in train:
        n = dither_period_samples(tr)
        ys.append(dither_period_mean(tr.get("clutch_pressure_bar"), n))
        ps.append(dither_period_mean(phys.predict(tr), n))
    physics_rmse = pressure_metrics(np.concatenate(ys), np.concatenate(ps))["rmse_bar"]
    assert rm < 0.5 * physics_rmse  # the residual model removes most of the physics error


def test_hybrid_declares_the_experiments_its_physics_was_fitted_on(train, tiny, tmp_path):
    """A hybrid on a physics fit that saw a test experiment has seen it too: its
    ``train_experiments_`` are its own traces and the physics fit's ``result_.train``,
    also after save / load and a refit of the loaded model, and the protocol refuses it.
    (Before: only the residual model's traces, so ``Protocol.score`` scored it.)"""
    from dataclasses import replace

    from fmu_support import fit_result
    from sklearn.base import clone

    from clutchlab.physics.fit import PhysicsFitter
    from clutchlab.validation import LeakageError, Protocol

    fitter = PhysicsFitter.load(replace(fit_result(), train=["medium_30Hz_A"]).to_json())
    residual = SVCPartitionedGP(features=HYBRID_FEATURES, **SMALL)
    model = HybridModel(physics=fitter, residual=residual, form="residual").fit(train)
    own = [t.name for t in train]
    assert model.train_experiments_ == [*own, "medium_30Hz_A"]
    assert model.residual_.train_experiments_ == own  # the residual model saw the traces
    protocol = Protocol(tiny)
    for leaky in (model, fitter):
        with pytest.raises(LeakageError, match="medium_30Hz_A"):
            protocol.score("hybrid", leaky)
    model.save(tmp_path / "h.json")
    loaded = load_model(tmp_path / "h.json")
    assert loaded.train_experiments_ == model.train_experiments_
    assert loaded.physics_.train_experiments_ == ["medium_30Hz_A"]
    with pytest.raises(LeakageError, match="medium_30Hz_A"):
        protocol.score("hybrid", loaded)
    refit = clone(loaded).set_params(form="physics").fit(train)  # the saved physics remembers
    assert "medium_30Hz_A" in refit.train_experiments_
    doc = json.loads((tmp_path / "h.json").read_text())
    doc["state"]["physics"]["train_experiments"] = "medium_30Hz_A"  # not a list: refused
    (tmp_path / "h.json").write_text(json.dumps(doc))
    with pytest.raises(ModelError, match=r"physics\.train_experiments: must be a list"):
        load_model(tmp_path / "h.json")
    # A physics fitted on the training experiments only: nothing is added, nothing refused.
    clean = PhysicsFitter.load(replace(fit_result(), train=own).to_json())
    ok = HybridModel(physics=clean, residual=residual, form="residual").fit(train)
    assert ok.train_experiments_ == own
    assert np.isfinite(protocol.score("hybrid", ok).metrics["rmse_bar"])


def test_hybrid_needs_physics_outputs_it_cannot_get(train):
    class PressureOnly:
        def predict(self, trace):
            return np.full(len(trace), 5.0)

    pilot = SVCPartitionedGP(features=("current_mA", "physics_bar", "physics_pilot_bar"))
    with pytest.raises(ModelError, match="pilot"):
        HybridModel(physics=PressureOnly(), residual=pilot).fit(train)
    default = SVCPartitionedGP(features=HYBRID_FEATURES, **SMALL)
    # (residual form pinned: against a constant "physics" the standalone form rightly wins)
    ok = HybridModel(physics=PressureOnly(), residual=default, form="residual").fit(train)
    assert ok.feature_names_ == list(HYBRID_FEATURES)  # the default needs no pilot pressure


def test_hybrid_kernel_is_the_default_residual_models_and_its_standalone_forms():
    """``kernel`` changes the kernel of the default residual model and of the standalone
    form made from it (the paper pipeline), nothing else; with a given residual model it is
    refused (that model carries its own)."""
    plain, rq = HybridModel(), HybridModel(kernel="rq")
    res, res0 = rq._residual(), plain._residual()
    assert res.kernel == "rq"
    assert {k: v for k, v in res.get_params().items() if k != "kernel"} == {
        k: v for k, v in res0.get_params().items() if k != "kernel"
    }
    assert res.latch_model == "classifier" and res.latched_reference == "none"
    alone, alone0 = rq._standalone(), plain._standalone()
    assert alone.kernel == "rq"
    assert {k: v for k, v in alone.get_params().items() if k != "kernel"} == {
        k: v for k, v in alone0.get_params().items() if k != "kernel"
    }
    given = HybridModel(residual=SVCPartitionedGP(features=HYBRID_FEATURES), kernel="rq")
    with pytest.raises(ModelError, match="given residual model carries its own"):
        given._residual()


# -- persistence and single steps ------------------------------------------------------------


@pytest.mark.parametrize("name", list(VARIANTS))
def test_save_load_round_trip_gives_identical_predictions(name, fitted, tiny, tmp_path):
    model = fitted[name]
    path = tmp_path / "m.json"
    model.save(path)
    assert (tmp_path / "m.npz").exists()
    doc = json.loads(path.read_text())
    assert doc["class"] == type(model).__name__ and doc["format"] == "clutchlab.residual_ml"
    loaded = type(model).load(path)
    tr = tiny["medium_70Hz_B"]
    np.testing.assert_array_equal(loaded.predict(tr), model.predict(tr))
    _, s1 = model.predict(tr, return_std=True)
    _, s2 = loaded.predict(tr, return_std=True)
    np.testing.assert_allclose(s2, s1, rtol=1e-9, atol=1e-12)
    assert loaded.get_params(deep=False).keys() == model.get_params(deep=False).keys()
    with np.load(tmp_path / "m.npz", allow_pickle=False) as arrays:
        assert arrays.files  # readable without pickle


def test_save_refuses_a_name_that_writes_over_its_arrays_or_a_file_it_did_not_write(
    fitted, tmp_path
):
    """``save_model(model, "x.npz")`` wrote the JSON over the NPZ (``x.npz`` with suffix
    ``.npz`` is itself) and reported success; a file of the user's at either name was
    replaced. Both are refused before anything is written; clutchlab's own model files
    are replaced as before."""
    model = fitted["gp_base"]
    for name in ("x.npz", "x.NPZ"):
        with pytest.raises(OutputError, match=r"give the JSON's name \(e\.g\. x\.json"):
            save_model(model, tmp_path / name)
    with pytest.raises(OutputError, match="not a file name"):
        save_model(model, "")
    assert not list(tmp_path.iterdir())  # nothing written
    mine = tmp_path / "notes.json"
    mine.write_text('{"mine": 1}\n')
    with pytest.raises(OutputError, match=r"notes\.json: exists and is not a clutchlab model"):
        model.save(mine)
    assert mine.read_text() == '{"mine": 1}\n' and not (tmp_path / "notes.npz").exists()
    arrays = tmp_path / "m.npz"
    np.savez(arrays, a=np.arange(3.0))
    before = arrays.read_bytes()
    with pytest.raises(OutputError, match=r"m\.npz: exists and is not the arrays file"):
        save_model(model, tmp_path / "m.json")
    assert arrays.read_bytes() == before and not (tmp_path / "m.json").exists()
    (tmp_path / "d.npz").mkdir()  # a folder where the arrays would go
    with pytest.raises(OutputError, match="is a folder"):
        save_model(model, tmp_path / "d.json")
    assert not (tmp_path / "d.json").exists()
    own = tmp_path / "own.json"
    save_model(model, own)
    assert save_model(model, own) == tmp_path / "own.npz"  # its own files: replaced
    assert load_model(own).train_experiments_ == model.train_experiments_


def test_load_rejects_other_files(tmp_path, fitted):
    bad = tmp_path / "x.json"
    bad.write_text('{"format": "something else"}')
    with pytest.raises(ModelError, match="not a clutchlab"):
        load_model(bad)
    fitted["gp_base"].save(tmp_path / "g.json")
    with pytest.raises(ModelError, match="not a SVCPartitionedGP"):
        SVCPartitionedGP.load(tmp_path / "g.json")


def test_step_predictor_matches_batch(fitted, tiny):
    tr = tiny["medium_30Hz_A"]
    for name in ("gp_didt", "paper_svc_gp"):
        model = fitted[name]
        step = step_predictor(model)
        F = model._trace_matrix(tr)[::97]
        line = tr.get("line_pressure_bar")[::97]
        ref = line if getattr(model, "latched_reference_", "none") == "line" else None
        exact = model._predict_matrix(
            F, path=False, return_std=False, **({"ref": ref} if ref is not None else {})
        )
        got = np.array([step(x, line_bar=v) for x, v in zip(F, line, strict=True)])
        np.testing.assert_allclose(got, exact, atol=1e-9)
    # paper_svc_gp follows line pressure on its latched plateau: the step needs it.
    assert fitted["paper_svc_gp"].latched_reference_ == "line"
    with pytest.raises(ModelError, match="line_bar"):
        for x in model._trace_matrix(tr):
            step(x)


def test_classifier_comparison_table_and_figure(train, tmp_path):
    res = compare_classifiers(list(train), names=["logistic_regression", "rbf_svc"])
    assert [r["name"] for r in res.rows] == ["logistic_regression", "rbf_svc"]
    for r in res.rows:
        assert 0.5 < r["accuracy"] <= 1.0 and r["min_accuracy"] <= r["accuracy"]
    res.to_csv(tmp_path / "c.csv")
    assert (tmp_path / "c.csv").read_text().splitlines()[0].startswith("name,label,accuracy")
    fig = res.figure(max_points=500)
    assert len(fig.axes) == 2 and "0." in fig.axes[0].texts[0].get_text()
    # two panels side by side in a figure two panels wide (it was three wide, one empty);
    # the accuracy on a box, readable over the points
    assert fig.get_size_inches()[0] == pytest.approx(2 * 4.2)
    assert fig.axes[0].texts[0].get_bbox_patch() is not None
    with pytest.raises(DataError, match="at least 2"):
        compare_classifiers([train[0]])


def test_classifier_comparison_is_the_same_on_worker_processes(train):
    names = ["discretized_linear_svc", "gradient_boosting"]
    here = compare_classifiers(list(train), names=names, workers=1)
    forked = compare_classifiers(list(train), names=names, workers=2)
    drop = ("fit_s",)
    assert [{k: v for k, v in r.items() if k not in drop} for r in here.rows] == [
        {k: v for k, v in r.items() if k not in drop} for r in forked.rows
    ]
    assert here.per_experiment == forked.per_experiment
    X = here._data[0]
    for name in names:  # the final classifiers came back from the workers whole
        np.testing.assert_array_equal(here._final[name].predict(X), forked._final[name].predict(X))


def test_gp_hyperparameters_by_part(fitted, train):
    assert set(fitted["gp_base"].gp_hyperparameters()) == {"gp", "variance_floor"}
    plain = GPBaseline(residual_variance="none", n_hyper=200, max_points=200)
    assert set(plain.fit(train).gp_hyperparameters()) == {"gp"}
    assert set(fitted["paper_svc_gp"].gp_hyperparameters()) == {"unlatched", "latched"}
    parts = fitted["hybrid"].gp_hyperparameters()
    assert set(parts) == {"residual.unlatched", "residual.latched"}
    for h in parts.values():
        assert {"kernel", "length_scales", "noise_var", "at_bounds"} <= set(h)
    flat = fitted["hybrid"].hyperparameters_at_bounds()
    assert len(flat) == sum(len(h["at_bounds"]) for h in parts.values())


def test_a_length_scale_on_its_bound_names_its_input(fitted, monkeypatch):
    """``residual.unlatched: length_scale[4] (upper bound 1e+03)`` left the user to count
    the features; the entry now names the input."""
    model = fitted["paper_svc_gp"]
    at = ["length_scale[1] (upper bound 1e+03)", "alpha (lower bound 0.01)"]
    monkeypatch.setattr(
        type(model), "gp_hyperparameters", lambda self: {"latched": {"at_bounds": at}}
    )
    name = model.feature_names_[1]
    # an upper-bound length scale also says what it means (the feature hardly matters)
    upper = ": the prediction hardly changes along this feature"
    said = model.hyperparameters_at_bounds()
    assert said[0].startswith(f"latched: length_scale[1] = {name} (upper bound 1e+03){upper}")
    assert said[1:] == ["latched: alpha (lower bound 0.01)"]
    hybrid = fitted["hybrid"]
    inner = hybrid.residual_
    monkeypatch.setattr(
        type(inner), "gp_hyperparameters", lambda self: {"unlatched": {"at_bounds": at[:1]}}
    )
    (said,) = hybrid.hyperparameters_at_bounds()
    named = f"residual.unlatched: length_scale[1] = {inner.feature_names_[1]} (upper bound 1e+03)"
    assert said.startswith(named + upper), said


def test_paper_faithful_variant_is_the_published_stage_3():
    from clutchlab.residual_ml.features import DIDT_FEATURES

    m = make_variant("paper_faithful")
    assert isinstance(m, SVCPartitionedGP)
    assert (m.kernel, m.lag_s, m.latch_model, m.latched_reference) == (
        "rq",
        0.0,
        "classifier",
        "none",
    )
    assert tuple(m.features) == DIDT_FEATURES  # the nominal current, no lag
    assert make_variant("paper_faithful", kernel="rbf").kernel == "rbf"
