"""The predictive std of the single GPs (``gp_base``, ``gp_didt``) beyond the GP's own: the
residual-variance floor from leave-one-experiment-out residuals (``residual_variance``) and
the rate bridge between trained ramp rates (``rate_uncertainty``)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from synthetic import tiny_stand

from clutchlab.errors import ModelError, ModelFileError
from clutchlab.residual_ml import GPBaseline, GPWithDerivative, load_model
from clutchlab.residual_ml.estimators import mean_only
from clutchlab.residual_ml.local_gp import LocalGPRegressor
from clutchlab.residual_ml.residual_variance import (
    LOG_CHI2_1_MEAN,
    fit_variance_floor,
    variance_floor,
)

SMALL = {"n_hyper": 300, "max_points": 300}


@pytest.fixture(scope="module")
def data():
    return tiny_stand(5)


@pytest.fixture(scope="module")
def fitted(data):
    train = data.select(ramps=["fast", "slow"])
    return {
        "default": GPWithDerivative(**SMALL).fit(train),
        "gp": GPWithDerivative(rate_uncertainty="none", residual_variance="none", **SMALL).fit(
            train
        ),
        "floor": GPWithDerivative(rate_uncertainty="none", **SMALL).fit(train),
    }


def _coverage(model, traces) -> dict:
    from clutchlab.validation import AnalysisSettings, ExperimentReference, interval_coverage

    s = AnalysisSettings()
    counts: dict = {}
    for trace in traces:
        ref = ExperimentReference.of(trace, s)
        mean, std = model.predict(trace, return_std=True)
        pm = ref.period_mean
        got = interval_coverage(
            ref.time_s, pm(ref.line_bar), ref.measured_mean_bar, pm(mean), pm(std), s
        )
        for region, (i, n) in got.items():
            c = counts.setdefault(region, [0, 0])
            c[0] += i
            c[1] += n
    return {region: i / n for region, (i, n) in counts.items()}


def test_a_gp_conditioned_on_its_own_data_is_itself_and_on_less_differs():
    rng = np.random.default_rng(0)
    X = rng.uniform(0, 10, (400, 2))
    y = np.sin(X[:, 0]) + 0.1 * X[:, 1] + rng.normal(0, 0.05, 400)
    gp = LocalGPRegressor(kernel="rbf", random_state=0).fit(X, y)
    Xq = rng.uniform(0, 10, (50, 2))
    before = gp.predict(Xq)
    same = gp.conditioned_on(X, y)
    np.testing.assert_allclose(same.predict(Xq), before, atol=1e-9)
    np.testing.assert_array_equal(same.theta_, gp.theta_)  # nothing optimized
    half = gp.conditioned_on(X[X[:, 0] < 5], y[X[:, 0] < 5])
    far = Xq[:, 0] > 7
    assert np.abs(half.predict(Xq[far]) - before[far]).max() > 0.3  # it lost that data
    np.testing.assert_array_equal(gp.predict(Xq), before)  # the original is unchanged
    _, s = half.predict(Xq, return_std=True)
    assert (s[far] > s[~far].max()).all()  # its std is its own: large where it has no data


def test_the_variance_floor_estimates_the_residual_variance_where_it_is():
    """Residuals with a std of 0.05 bar on one side and 0.5 bar on the other: the floor
    recovers both within 25 % (ln r² is biased by E[ln χ²₁], which it adds back)."""
    rng = np.random.default_rng(1)
    X = rng.uniform(0, 10, (4000, 1))
    sd = np.where(X[:, 0] < 5, 0.05, 0.5)
    floor = fit_variance_floor(X, rng.normal(0, sd))
    got = np.sqrt(variance_floor(floor, np.array([[2.0], [8.0]])))
    np.testing.assert_allclose(got, [0.05, 0.5], rtol=0.25)
    assert LOG_CHI2_1_MEAN == pytest.approx(-np.euler_gamma - np.log(2))


def test_the_floor_and_the_bridge_widen_the_band_and_keep_the_mean(data, fitted):
    gp, floor, default = fitted["gp"], fitted["floor"], fitted["default"]
    assert gp.variance_floor_ is None and floor.variance_floor_ is not None
    assert len(default.train_log_rates_) == 2
    trace = data["medium_30Hz_A"]
    m0, s0 = gp.predict(trace, return_std=True)
    m1, s1 = floor.predict(trace, return_std=True)
    m2, s2 = default.predict(trace, return_std=True)
    np.testing.assert_array_equal(m1, m0)
    np.testing.assert_array_equal(m2, m0)
    assert (s1 >= s0 - 1e-12).all() and (s2 >= s1 - 1e-12).all()
    # the bridge adds nothing where the current holds
    holds = np.abs(default._trace_matrix(trace)[:, default.feature_names_.index("didt_mA_s")])
    np.testing.assert_allclose(s2[holds < 1.0], s1[holds < 1.0])
    # on the medium ramp (between the trained rates) both raise the latched and window coverage
    medium = data.select(ramps=["medium"])
    cov = {k: _coverage(fitted[k], medium) for k in ("gp", "floor", "default")}
    assert cov["floor"]["latched"] > cov["gp"]["latched"] + 0.05
    assert cov["default"]["latch_window"] > cov["gp"]["latch_window"] + 0.2


def test_gp_base_has_the_floor_but_no_rate_term(data):
    """``gp_base`` has no dI/dt feature: no trained rates, no bridge; the floor applies."""
    model = GPBaseline(**SMALL).fit(data.select(ramps=["fast", "slow"]))
    assert model.train_log_rates_ == [] and model.variance_floor_ is not None


def test_save_load_keeps_the_floor_and_the_rates_and_checks_them(tmp_path, data, fitted):
    model = fitted["default"]
    model.save(tmp_path / "m.json")
    loaded = load_model(tmp_path / "m.json")
    assert loaded.train_log_rates_ == model.train_log_rates_
    trace = data["medium_70Hz_B"]
    np.testing.assert_array_equal(
        loaded.predict(trace, return_std=True)[1], model.predict(trace, return_std=True)[1]
    )
    doc = json.loads((tmp_path / "m.json").read_text())
    doc["state"]["variance_floor"]["n_features_in"] = 2
    doc["params"]["residual_variance"] = "wide"
    (tmp_path / "m.json").write_text(json.dumps(doc))
    with pytest.raises(ModelFileError) as err:
        load_model(tmp_path / "m.json")
    assert "variance_floor" in str(err.value) and "residual_variance" in str(err.value)


def test_older_files_load_with_the_gp_std(tmp_path, data, fitted):
    """Files written before the floor and the bridge: the GP's own std, as then."""
    fitted["default"].save(tmp_path / "m.json")
    doc = json.loads((tmp_path / "m.json").read_text())
    del doc["state"]["variance_floor"], doc["state"]["train_log_rates"]
    for p in ("rate_uncertainty", "pressure_rate_scale", "residual_variance"):
        del doc["params"][p]
    (tmp_path / "m.json").write_text(json.dumps(doc))
    npz = tmp_path / doc["arrays"]
    arrays = dict(np.load(npz))
    np.savez(npz, **{k: v for k, v in arrays.items() if not k.startswith("floor.")})
    old = load_model(tmp_path / "m.json")
    assert old.variance_floor_ is None and old.train_log_rates_ == []
    trace = data["medium_30Hz_A"]
    np.testing.assert_allclose(
        old.predict(trace, return_std=True)[1], fitted["gp"].predict(trace, return_std=True)[1]
    )


def test_bad_settings_are_refused_and_folds_skip_the_std_fits(data):
    train = data.select(ramps=["fast"])
    with pytest.raises(ModelError, match="residual_variance must be"):
        GPWithDerivative(residual_variance="wide", **SMALL).fit(train)
    with pytest.raises(ModelError, match="rate_uncertainty must be"):
        GPBaseline(rate_uncertainty="wide", **SMALL).fit(train)
    est = mean_only(GPWithDerivative(max_points=7))
    assert est.rate_uncertainty == "none" and est.residual_variance == "none"
    assert est.max_points == 7
