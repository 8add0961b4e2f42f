"""Discovery on long data: screening on the pre-fit subset, decisions on every training
experiment; a discovery that starts from a fit already made (issue 17: speed, the demo)."""

from __future__ import annotations

import copy
import json
from dataclasses import replace
from types import SimpleNamespace

import pytest

from clutchlab.cli import main
from clutchlab.data import load_dataset
from clutchlab.errors import FitError
from clutchlab.physics import CircuitModel
from clutchlab.physics.fit import FitSettings, PhysicsFitter, prefit_subset
from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, write_stand
from clutchlab.validation.discover import DiscoverySettings, discover
from clutchlab.validation.discover.variant import AugmentedHybrid, AugmentedPhysics

pytestmark = pytest.mark.filterwarnings("ignore::clutchlab.errors.FitWarning")

RAMPS = (
    RampProfile("fast", 1.5, 0.3),
    RampProfile("medium", 3.0, 0.3),
    RampProfile("slow", 6.0, 0.3),
)
CANDIDATES = ("supply_droop", "latch_threshold_drift")


@pytest.fixture(scope="module")
def stand_dir(tmp_path_factory):
    """Three dither settings × three ramps, supply droop undeclared: six training experiments."""
    config = StandConfig(
        builtin_effects=False,
        effects=("supply_droop",),
        settings=(DitherSetting(50.0, "B"), DitherSetting(70.0, "A"), DitherSetting(30.0, "C")),
        ramps=RAMPS,
        seed=5,
    )
    out = tmp_path_factory.mktemp("screening") / "stand"
    write_stand(out, config, progress=False, figure=False)
    return out


@pytest.fixture(scope="module")
def stand(stand_dir):
    return load_dataset(stand_dir)


def _settings(**kw) -> DiscoverySettings:
    fit = FitSettings(progress=False, free=("vfs_K_m", "reg_F0"), max_iter=8, workers=1)
    return DiscoverySettings(
        **{"fit": fit, "progress": False, "candidates": CANDIDATES, "max_effects": 1, **kw}
    )


def _budget(stand) -> int:
    """One sample short of the training data: the subset leaves the longest one out."""
    return sum(len(t) for t in stand if t.ramp in ("fast", "slow")) - 1


def _train(stand) -> list:
    return [t for t in stand if t.ramp in ("fast", "slow")]


@pytest.fixture(scope="module")
def base_fit(stand):
    """The base model fitted on the training experiments with the discoveries' fit settings
    (what ``discover`` fits first when it is given no fit; see
    ``test_a_discovery_fits_its_baseline_as_given_fits_are_fitted``)."""
    return PhysicsFitter(CircuitModel(), _settings().fit).fit(_train(stand)).result_


@pytest.fixture(scope="module")
def other_fit(stand):
    """The same fit on half of the training experiments."""
    return PhysicsFitter(CircuitModel(), _settings().fit).fit(_train(stand)[:3]).result_


@pytest.fixture(scope="module")
def screened(stand, base_fit):
    return discover(stand, settings=_settings(screen_samples=_budget(stand)), baseline=base_fit)


def test_the_subset_takes_every_ramp_and_is_all_data_within_the_budget(stand):
    train = [t for t in stand if t.ramp in ("fast", "slow")]
    sub = prefit_subset(train, 1)
    assert sorted(t.ramp for t in sub) == ["fast", "slow"]
    assert prefit_subset(train, 0) == train
    assert prefit_subset(train, sum(len(t) for t in train)) == train


def test_screening_refits_stop_on_a_short_cost_plateau():
    """The screening's refits stop when their cost moved less than the pre-fit's tolerance
    over their last two iterations (the pre-fit's own plateau test spans more), or at
    their short budget."""
    from clutchlab.physics.fit import prefit_settings
    from clutchlab.validation.discover.screen import SCREEN_PLATEAU_ITER, screen_settings

    settings = _settings()
    sub = screen_settings(settings)
    assert sub.plateau_iter == SCREEN_PLATEAU_ITER == 2
    assert prefit_settings(settings.fit).plateau_iter > sub.plateau_iter
    assert sub.prefit_obj_change_tol == settings.fit.prefit_obj_change_tol
    assert sub.max_iter == min(settings.fit.max_iter, settings.screen_max_iter)


def test_a_staged_fit_keeps_its_pre_fit_optimum(stand):
    """``PhysicsFitter.prefit_``: the pre-fit's subset, best iterate and status when the fit
    was staged; None when the data fit in the pre-fit's budget (one stage)."""
    train = _train(stand)
    budget = _budget(stand)
    fit = replace(_settings().fit, prefit_samples=budget)
    fitter = PhysicsFitter(CircuitModel(), fit).fit(train)
    pre = fitter.prefit_
    assert pre is not None and pre.model.key == CircuitModel().key
    assert pre.experiments == tuple(t.name for t in prefit_subset(train, budget))
    assert set(fit.free) <= set(pre.params) and pre.status
    one = PhysicsFitter(CircuitModel(), replace(fit, prefit_samples=0)).fit(train)
    assert one.prefit_ is None


def test_a_discovery_that_fits_its_baseline_takes_the_pre_fit_as_its_subset_reference(stand):
    """Where the baseline fit's pre-fit ran on the screening subset, the subset reference is
    the better of that optimum and the current fit (no continuation is fitted); a discovery
    given its baseline continues the current fit there (``screened``, below)."""
    budget = _budget(stand)
    fit = replace(_settings().fit, prefit_samples=budget)
    settings = _settings(fit=fit, screen_samples=budget, candidates=("supply_droop",))
    res = discover(stand, settings=settings)
    info = res.iterations[0].reference["screening"]
    assert info["kind"] in (
        "the current fit's own pre-fit on the subset",
        "current fit on the subset (its pre-fit's optimum is not lower)",
    ), info["kind"]
    assert "iterations" not in info  # no continuation ran
    assert info["rss_bar2"] <= info["rss_before_bar2"]
    assert info["experiments"] == [t.name for t in prefit_subset(_train(stand), budget)]


def test_a_discovery_given_its_baseline_continues_it_on_the_subset(screened):
    info = screened.iterations[0].reference["screening"]
    assert info["kind"].startswith("current fit") and info["iterations"] >= 1


def test_screening_refits_on_the_subset_and_decides_on_every_training_experiment(screened):
    it = screened.iterations[0]
    screening = it.reference["screening"]
    assert len(screening["experiments"]) == 5 and screening["subset"].startswith("5 of 6")
    refitted = [c for c in it.candidates if c.refit]
    assert refitted, "a significant candidate was refitted"
    for c in refitted:
        first = c.refit if c.refit.get("scope") == "screening" else c.refit["screen"]
        assert first["scope"] == "screening" and "delta_bic" in first
    assert it.effect == "supply_droop", it.decision
    chosen = next(c for c in it.candidates if c.effect == it.effect)
    # the decision's verdict is the one on all four training experiments
    assert chosen.refit["delta_bic"] < 0 and "scope" not in chosen.refit
    assert chosen.refit["screen"]["scope"] == "screening"
    assert chosen.refit["loeo_rss_bar2"] < it.reference["loeo_rss_bar2"]
    assert set(it.after.residual.experiments) == set(screened.train)
    assert len(screened.train) == 6
    assert it.after.test["rmse_bar"] < it.before.test["rmse_bar"]


def test_the_training_jacobian_is_computed_only_where_it_is_used(stand, base_fit, screened):
    # no candidate to score: nothing needs the sensitivities on every training experiment
    settings = _settings(screen_samples=_budget(stand), candidates=())
    res = discover(stand, settings=settings, baseline=base_fit)
    assert res.iterations[0].decision == "no candidates left"
    assert res.baseline.residual.jacobian is None
    # a confirmation on every training experiment is judged against them
    before = screened.iterations[0].before.residual
    assert before.jacobian is not None and before.jacobian.shape[0] == before.n


def test_no_screening_when_the_data_fit_in_the_budget(stand, base_fit):
    res = discover(stand, settings=_settings(screen_samples=0), baseline=base_fit)
    it = res.iterations[0]
    assert "screening" not in it.reference
    assert all("scope" not in c.refit and "screen" not in c.refit for c in it.candidates)


def test_a_discovery_starts_from_a_given_fit_and_refuses_one_made_on_other_data(
    stand, base_fit, other_fit, screened
):
    settings = _settings(screen_samples=_budget(stand))
    assert screened.baseline.fit is base_fit  # no second baseline fit
    assert screened.added == ["supply_droop"]
    with pytest.raises(FitError, match="other experiments"):
        discover(stand, settings=settings, baseline=other_fit)
    with pytest.raises(FitError, match="lacks the model's effect"):
        discover(stand, CircuitModel().with_effects("sensor_lag"), settings, baseline=base_fit)


def test_a_discovery_fits_its_baseline_as_given_fits_are_fitted(stand, base_fit):
    """Given no fit, ``discover`` fits the base model itself: the same fit as ``base_fit``
    (so the discoveries above, which start from it, are the ones it would run)."""
    res = discover(stand, settings=_settings(max_effects=0))
    assert res.iterations[0].decision == "effect limit reached"
    assert res.baseline.fit.free == base_fit.free
    for name, value in base_fit.values.items():
        assert res.baseline.fit.values[name] == pytest.approx(value, rel=1e-9, abs=1e-12)


class _FittedHybrid:
    """Stands for the ``hybrid`` variant fitted on the same experiments."""

    residual = None

    def __init__(self, names, fit):
        self.train_experiments_ = sorted(names)
        self.physics = SimpleNamespace(result_=fit)  # the physics_fitted it stands on

    def predict(self, trace, return_std=False):  # pragma: no cover - not called here
        raise AssertionError


def test_the_augmented_hybrid_is_the_hybrid_when_nothing_is_added(stand, base_fit):
    settings = _settings(screen_samples=_budget(stand), candidates=("latch_threshold_drift",))
    train, fit = _train(stand), base_fit
    hybrid = _FittedHybrid((t.name for t in train), fit)
    model = AugmentedHybrid(AugmentedPhysics(None, settings, baseline=fit), hybrid=hybrid)
    model.fit(train)
    assert model.physics_.effects_ == [] and model.reused_hybrid_
    assert model.hybrid_ is hybrid
    # a hybrid fitted on other experiments, or with another residual model, is not reused
    model.hybrid = _FittedHybrid((t.name for t in train[:3]), fit)
    assert not model._unchanged(train)
    model.hybrid, model.residual = hybrid, object()
    assert not model._unchanged(train)
    # nor one standing on another physics fit
    model.hybrid, model.residual = _FittedHybrid((t.name for t in train), copy.copy(fit)), None
    assert not model._unchanged(train)


def test_cli_discover_starts_from_a_fit_physics_json(
    base_fit, other_fit, stand_dir, tmp_path, capsys
):
    base_fit.to_json(tmp_path / "fit.json")
    argv = ["discover", str(stand_dir), "--out", str(tmp_path / "rep"), "--quiet"]
    argv += ["--candidates", "latch_threshold_drift", "--max-effects", "0", "--max-iter", "3"]
    argv += ["--free", "vfs_K_m,reg_F0", "--json", str(tmp_path / "d.json")]
    assert main([*argv, "--physics-model", str(tmp_path / "fit.json")]) == 0
    doc = json.loads((tmp_path / "d.json").read_text())
    # no effect may be added (--max-effects 0): the final model is the given fit, not a refit
    assert doc["added"] == []
    for name, value in base_fit.values.items():
        assert doc["final"]["values"][name] == pytest.approx(value, rel=1e-12, abs=1e-12)
    other_fit.to_json(tmp_path / "other.json")
    argv[3] = str(tmp_path / "rep2")
    assert main([*argv, "--physics-model", str(tmp_path / "other.json")]) != 0
    assert "other experiments" in capsys.readouterr().err
    assert not (tmp_path / "rep2").exists()


def test_period_mean_metrics_are_the_same_on_forked_workers(stand, base_fit):
    """The before / after metrics simulate their traces on forked workers: the same numbers
    and figure curves as in one process."""
    from clutchlab.validation.discover import period_mean_metrics

    model, params = base_fit.model(), base_fit.params()
    one = period_mean_metrics(model, params, list(stand), workers=1)
    two = period_mean_metrics(model, params, list(stand), workers=2)
    assert one[0] == two[0]
    assert list(one[1]) == list(two[1]) == [t.name for t in stand]
    for name, (cur, res) in one[1].items():
        assert (cur == two[1][name][0]).all() and (res == two[1][name][1]).all()
