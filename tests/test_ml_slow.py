"""Must-shows of the paper pipeline on the full default stand dataset (slow).

Training: the 18 fast + slow experiments; test: the 9 medium-ramp experiments, scored by
the RMSE of the dither-period-mean clutch pressure. Measured values: BENCHMARKS.md
("Local GP / paper pipeline"); regenerate with ``python -m pytest -m slow
tests/test_ml_slow.py -s``.
"""

from __future__ import annotations

import pytest

from clutchlab.physics.fit import FitSettings, PhysicsFitter
from clutchlab.physics.stand import StandConfig, run_stand
from clutchlab.residual_ml import (
    PhysicsPredictor,
    compare_classifiers,
    make_variant,
    score_traces,
)

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def stand():
    return run_stand(StandConfig(), progress=False).dataset


@pytest.fixture(scope="module")
def split(stand):
    return list(stand.select(ramps=["fast", "slow"])), list(stand.select(ramps=["medium"]))


def _medium_rmse(split, name, **params) -> float:
    train, test = split
    model = make_variant(name, **params).fit(train)
    rmse = score_traces(model, test)["overall"]["rmse_bar"]
    print(f"{name} {params or ''}: medium RMSE {rmse:.4f} bar")
    return rmse


@pytest.fixture(scope="module")
def medium(split):
    """Medium-ramp RMSE (bar) of every variant with its default settings."""
    return {n: _medium_rmse(split, n) for n in ("gp_base", "gp_didt", "paper_svc_gp", "hybrid")}


def test_must_show_1_classifier_table(split):
    res = compare_classifiers(split[0])
    print("\n" + res.table())
    acc = {r["name"]: r["accuracy"] for r in res.rows}
    assert len(acc) == 6
    assert acc["rbf_svc"] >= 0.99
    assert acc["gradient_boosting"] >= 0.99


def test_must_show_2_both_later_stages_beat_the_baseline(medium):
    """Stages 2 and 3 (lagged current, dI/dt, direction) beat stage 1 on the unseen rate."""
    assert medium["gp_didt"] < 0.5 * medium["gp_base"]
    assert medium["paper_svc_gp"] < 0.5 * medium["gp_base"]


def test_must_show_2_paper_order(medium):
    """The paper's full order gp_base > gp_didt > paper_svc_gp on the medium ramp.

    Not reproduced when this was written as a strict xfail (0.274 against 0.247 bar for the
    last two, on the defaults of then); reproduced on today's, all chosen inside the training
    set (measured in session 66: 0.708 > 0.247 > 0.237 bar)."""
    assert medium["gp_base"] > medium["gp_didt"] > medium["paper_svc_gp"]


def test_must_show_2_rq_versus_rbf(split, medium):
    """RQ against RBF for every local-GP variant, reported; both kernels beat stage 1."""
    other = {"gp_base": "rq", "gp_didt": "rbf", "paper_svc_gp": "rq"}
    alt = {n: _medium_rmse(split, n, kernel=k) for n, k in other.items()}
    for n, k in other.items():
        print(f"{n}: default kernel {medium[n]:.4f} bar, {k} {alt[n]:.4f} bar")
    assert alt["gp_didt"] < medium["gp_base"] and alt["paper_svc_gp"] < medium["gp_base"]


def test_must_show_3_hybrid_beats_paper_model(medium, split):
    assert medium["hybrid"] <= medium["paper_svc_gp"]
    # with the paper's RQ kernel too: the default residual model and its standalone form
    # with that kernel (an SVCPartitionedGP with the standalone pipeline's defaults as the
    # residual takes a latch law that never sees the physics: 0.2525 bar, its standalone
    # form, measured in session 66)
    rq = _medium_rmse(split, "hybrid", kernel="rq")
    assert rq <= medium["paper_svc_gp"]


@pytest.fixture(scope="module")
def fitted_physics(split):
    """The physics model fitted on the training experiments only (issue 4's fitter)."""
    fitter = PhysicsFitter(settings=FitSettings(progress=False)).fit(split[0])
    return PhysicsPredictor.from_fitter(fitter)


def test_must_show_3_hybrid_on_fitted_physics(split, medium, fitted_physics):
    """The hybrid of issue 5 is the *fitted* physics plus a partitioned GP on its residual.
    (With the datasheet physics it measured 0.0958-0.1153 bar, at the 0.10 bound.)"""
    rmse = _medium_rmse(split, "hybrid", physics=fitted_physics)
    assert rmse <= medium["paper_svc_gp"]
    assert rmse <= 0.10
