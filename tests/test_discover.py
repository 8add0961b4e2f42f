"""Closing the loop (issue 7): the discovery machinery on a tiny dataset, and its statistics.

Fast tests. The tiny stand dataset has one undeclared effect (``supply_droop``, which
changes the dither-period-mean pressure by up to 0.45 bar at the stand's default
strength) and short ramps; the fit frees two parameters. The slow tests in
``test_discover_effects.py`` / ``test_discover_null.py`` check the science.
"""

from __future__ import annotations

import json
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from synthetic import make_trace

import clutchlab.validation.discover.loop as loop
import clutchlab.validation.discover.scoring as scoring
from clutchlab.cli import main
from clutchlab.data import load_dataset
from clutchlab.errors import FitError, SimulationError
from clutchlab.physics import CircuitModel
from clutchlab.physics.fit import FitSettings
from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, write_stand
from clutchlab.validation.discover import (
    DiscoverySettings,
    ResidualSet,
    alternative_note,
    discover,
    residual_problem,
    residual_set,
)
from clutchlab.validation.discover.refit import by_criterion
from clutchlab.validation.discover.residuals import (
    effective_size,
    integrated_time,
    loeo_errors,
    loeo_evidence,
    loeo_rss,
    loro_errors,
    point_sums_of_squares,
)
from clutchlab.validation.discover.scoring import Projector, profile_points, score_effect

TINY_RAMPS = (
    RampProfile("fast", 1.5, 0.3),
    RampProfile("medium", 3.0, 0.3),
    RampProfile("slow", 6.0, 0.3),
)
FREE = ("vfs_K_m", "reg_F0")
CANDIDATES = ("supply_droop", "latch_threshold_drift")
#: The issue's JSON keys of one iteration.
ITERATION_KEYS = {
    "effect",
    "candidates",
    "train_rmse_before_bar",
    "train_rmse_after_bar",
    "test_rmse_before_bar",
    "test_rmse_after_bar",
}


@pytest.fixture(scope="module")
def tiny_dir(tmp_path_factory):
    config = StandConfig(
        builtin_effects=False,
        effects=("supply_droop",),
        settings=(DitherSetting(50.0, "B"),),
        ramps=TINY_RAMPS,
        seed=3,
    )
    out = tmp_path_factory.mktemp("discover") / "stand"
    write_stand(out, config, progress=False, figure=False)
    return out


@pytest.fixture(scope="module")
def cli_run(tiny_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("discover_out")
    argv = [
        "discover",
        str(tiny_dir),
        "--out",
        str(out / "report"),
        "--json",
        str(out / "discovery.json"),
        "--max-effects",
        "1",
        "--free",
        ",".join(FREE),
        "--candidates",
        ",".join(CANDIDATES),
        "--max-iter",
        "5",
        "--quiet",
    ]
    code = main(argv)
    return code, out


def test_cli_refuses_an_invalid_substep_count_before_writing(tiny_dir, tmp_path, capsys):
    out = tmp_path / "report"
    code = main(["discover", str(tiny_dir), "--out", str(out), "--substeps", "0", "--quiet"])
    assert code == 2 and "substeps must be 1..16" in capsys.readouterr().err
    assert not out.exists()


def test_cli_writes_the_issue_json_and_a_report(cli_run):
    code, out = cli_run
    assert code == 0
    doc = json.loads((out / "discovery.json").read_text())
    assert isinstance(doc["unexplained"], bool)
    assert doc["iterations"], "at least one iteration"
    for it in doc["iterations"]:
        assert ITERATION_KEYS <= set(it)
        for key in ITERATION_KEYS - {"effect", "candidates"}:
            assert it[key] is None or it[key] >= 0.0
        assert it["expansions"][0] == "zero" and set(it["expansions"]) <= {"zero", "profile"}
    first = doc["iterations"][0]
    assert {c["effect"] for c in first["candidates"]} == set(CANDIDATES)
    for c in first["candidates"]:
        assert {"share", "statistic", "p_value", "novelty", "significant", "status"} <= set(c)
    report = out / "report"
    assert json.loads((report / "discovery.json").read_text()) == doc
    html = (report / "report.html").read_text()
    assert "Iteration 0" in html and "supply_droop" in html
    assert "flexible alternatives" in html  # the evidence table's column (issue 17)
    assert "standard errors allow for the residuals&#x27; correlation over" in html  # escaped
    for kind in ("residuals", "evidence", "diagnostics"):
        png = report / f"iteration0_{kind}.png"
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_the_html_report_names_the_training_and_test_experiments(cli_run):
    _, out = cli_run
    doc = json.loads((out / "discovery.json").read_text())
    html = (out / "report" / "report.html").read_text()
    assert f"Training: {len(doc['train'])} experiments ({', '.join(doc['train'])})" in html
    assert f"test, only scored: {len(doc['test'])} ({', '.join(doc['test'])})" in html
    # the residual's RMS is not the training RMSE beside it: the report says why they differ
    assert "bar without the samples near latch snaps (the training RMSE includes them)" in html


def test_an_iteration_that_scored_no_candidate_has_no_empty_evidence_figure(cli_run):
    _, out = cli_run
    doc = json.loads((out / "discovery.json").read_text())
    report = out / "report"
    html = (report / "report.html").read_text()
    assert any(not it["candidates"] for it in doc["iterations"])  # the effect limit
    for k, it in enumerate(doc["iterations"]):
        evidence = report / f"iteration{k}_evidence.png"
        assert evidence.exists() == bool(it["candidates"])
        if not it["candidates"]:
            assert f"No candidate was scored ({it['decision']})." in html
            assert f"plot-iteration{k}_evidence" not in html


def test_the_report_says_whether_each_refit_converged(cli_run):
    _, out = cli_run
    doc = json.loads((out / "discovery.json").read_text())
    html = (out / "report" / "report.html").read_text()
    for it in doc["iterations"]:
        state = "converged" if it["fit_converged_after"] else "NOT converged"
        assert f"fit after: {it['fit_status_after']}, {state}" in html


def test_the_report_draws_every_figure_interactive_offline(cli_run):
    """Issue 19: report.html draws each iteration's figures with Plotly (embedded once) in
    headless Chromium with the network disabled; the PNGs stay for report.md."""
    from clutchlab.validation.render import find_browser, load_page

    browser = find_browser()
    assert browser is not None, "no headless Chromium: set CLUTCHLAB_CHROMIUM or install one"
    report = cli_run[1] / "report"
    html = (report / "report.html").read_text(encoding="utf-8")
    iterations = json.loads((report / "discovery.json").read_text())["iterations"]
    # residuals and diagnostics per iteration; evidence where candidates were scored
    n_figures = sum(3 if it["candidates"] else 2 for it in iterations)
    assert html.count("* plotly.js v") == 1 and "<img" not in html
    page = load_page(report / "report.html", browser)
    assert page.offline and page.plots == page.plots_drawn == page.figures == n_figures
    md = (report / "report.md").read_text(encoding="utf-8")
    assert md.count(".png)") == n_figures


def test_the_one_undeclared_effect_is_named_and_lowers_both_errors(cli_run):
    """Supply droop explains most of the residual; a latch threshold shift moves mainly the
    latch snaps, which the evidence leaves out."""
    _, out = cli_run
    first = json.loads((out / "discovery.json").read_text())["iterations"][0]
    assert first["effect"] == "supply_droop"
    assert first["train_rmse_after_bar"] < first["train_rmse_before_bar"]
    assert first["test_rmse_after_bar"] < first["test_rmse_before_bar"]
    by_name = {c["effect"]: c for c in first["candidates"]}
    assert by_name["supply_droop"]["share"] > by_name["latch_threshold_drift"]["share"]
    assert by_name["supply_droop"]["refit"]["delta_bic"] < 0


# ---- statistics with known answers --------------------------------------------------------
def test_integrated_time_of_white_noise_and_ar1():
    rng = np.random.default_rng(0)
    assert integrated_time(rng.standard_normal(20_000)) == pytest.approx(1.0, abs=0.15)
    phi = 0.8  # AR(1): τ = (1 + φ) / (1 − φ) = 9
    e = rng.standard_normal(50_000)
    x = np.empty_like(e)
    x[0] = e[0]
    for k in range(1, len(e)):
        x[k] = phi * x[k - 1] + e[k]
    assert integrated_time(x) == pytest.approx(9.0, rel=0.2)
    n_eff, _ = effective_size(np.concatenate([x, e[:1000]]), [(0, len(x)), (len(x), len(x) + 1000)])
    assert n_eff == pytest.approx(len(x) / 9.0 + 1000.0, rel=0.2)


def test_projector_removes_the_free_parameter_directions():
    rng = np.random.default_rng(1)
    j = rng.standard_normal((200, 3))
    j[:, 2] = j[:, 0] + j[:, 1]  # rank 2
    proj = Projector(j)
    assert np.allclose(proj(j), 0.0, atol=1e-10)
    v = rng.standard_normal(200)
    assert np.allclose(proj(proj(v)), proj(v))
    assert np.allclose(j.T @ proj(v), 0.0, atol=1e-9)


def test_invalid_settings_are_refused():
    with pytest.raises(FitError, match="both trained on and tested on"):
        DiscoverySettings(test_ramps=("slow",))
    with pytest.raises(FitError, match="alpha"):
        DiscoverySettings(alpha=0.0)


# ---- failure modes ----------------------------------------------------------------------
@pytest.fixture(scope="module")
def tiny(tiny_dir):
    return load_dataset(tiny_dir)


def _settings(**kw) -> DiscoverySettings:
    fit = FitSettings(progress=False, free=("reg_F0",), max_iter=3, workers=1)
    return DiscoverySettings(fit=fit, progress=False, **kw)


def test_no_training_ramps_is_a_clear_error(tiny):
    with pytest.raises(FitError, match="no training experiments"):
        discover(tiny.select(ramps=["medium"]), settings=_settings())


def test_a_candidate_that_fails_to_score_is_reported_not_raised(tiny, monkeypatch):
    train = list(tiny.select(ramps=["fast", "slow"]))
    model = CircuitModel()
    params = model.default_params()
    fit = _settings().fit
    base = residual_set(residual_problem(model, params, ("reg_F0",), train, fit), train, True)

    def boom(*args, **kwargs):
        raise SimulationError("state not finite at t = 0.1 s")

    monkeypatch.setattr(scoring, "_sensitivity", boom)
    out = score_effect(
        "stribeck_friction", model, dict(params.values), train, base, Projector(None), fit
    )
    assert out.status.startswith("failed: state not finite")
    assert not out.significant and out.share == 0.0


def test_a_candidate_whose_refit_fails_is_not_added(tiny, monkeypatch):
    real = loop.run_fit

    def failing(model, train, settings, free, start, fit=None, **kw):
        if "supply_droop" in model.effect_names:
            raise FitError("the model diverges at the start parameters")
        return real(model, train, settings, free, start, fit, **kw)

    monkeypatch.setattr(loop, "run_fit", failing)
    res = discover(tiny, settings=_settings(candidates=("supply_droop",), max_effects=1))
    (it,) = res.iterations
    assert it.effect is None
    assert res.added == []
    (cand,) = it.candidates
    assert cand.significant  # so it was refitted
    assert cand.refit["status"].startswith("failed: the model diverges")
    assert it.decision == "information criterion did not improve"


def test_no_effect_is_claimed_over_a_flexible_law_whose_refit_broke_down(tiny, monkeypatch):
    """The true supply droop beats the regulator pilot lag when that law is fitted; when
    its refit breaks down, the droop is not claimed (session 32)."""
    settings = _settings(candidates=("supply_droop",), max_effects=1)
    res = discover(tiny, settings=settings)
    it = res.iterations[0]
    assert res.added == ["supply_droop"] and it.effect == "supply_droop"
    (cand,) = it.candidates
    assert [r["law"] for r in cand.refit["alternatives"]] == ["reg_pilot_lag"]
    assert cand.refit["beats_alternatives"] is True

    def broken(alt, current, traces, settings, reference, fit=None):
        rss = 9.0 * reference.kept_rss
        return {"law": alt.law, "k": alt.k, "status": "Error_In_Step_Computation"} | {
            "iterations": 2,
            "rss_bar2": rss,
            "rss_ref_bar2": reference.kept_rss,
            "loeo_rss_bar2": rss,
        }

    monkeypatch.setattr(loop, "fit_alternative", broken)
    res = discover(tiny, settings=settings)
    assert res.added == []
    (it,) = res.iterations
    (cand,) = it.candidates
    assert cand.refit["beats_alternatives"] is False
    assert alternative_note(cand.refit) == "not compared: reg_pilot_lag's refit broke down"
    assert it.decision.startswith("not compared with a flexible law")
    assert (
        "supply_droop against reg_pilot_lag: Error_In_Step_Computation after 2 iterations"
        in it.decision
    )
    assert it.decision.endswith("no effect claimed")


@pytest.mark.parametrize(
    ("outcomes", "fitted", "note"),
    [
        ({"reg_pilot_lag": "match"}, ["reg_pilot_lag"], "matched by reg_pilot_lag"),
        (
            {"latch_free_thresholds": "match"},
            ["reg_pilot_lag", "latch_free_thresholds"],
            "matched by latch_free_thresholds",
        ),
        (
            {"reg_pilot_lag": "broken", "latch_free_thresholds": "match"},
            ["reg_pilot_lag", "latch_free_thresholds"],
            "matched by latch_free_thresholds",
        ),
        (
            {"reg_pilot_lag": "broken"},
            ["reg_pilot_lag", "latch_free_thresholds"],
            "not compared: reg_pilot_lag's refit broke down",
        ),
    ],
)
def test_a_matched_candidate_stops_at_the_first_law_that_matches_it(
    tiny, monkeypatch, outcomes, fitted, note
):
    """With the latch's preload and rate free, the supply droop meets two laws, the pilot
    lag (one parameter) first. Whichever law matches it, nothing is claimed, and the laws
    after the matching one are not refitted; a law whose refit broke down does not end the
    comparison, and is named only when no other law matches (session 33)."""
    settings = _settings(candidates=("supply_droop",), max_effects=1)
    settings = replace(settings, fit=replace(settings.fit, free=("reg_F0", "latch_F0", "latch_k")))
    calls = []

    def stub(alt, current, traces, settings, reference, fit=None):
        calls.append(alt.law)
        outcome = outcomes.get(alt.law, "beaten")
        rss = (1e-6 if outcome == "match" else 2.0) * reference.kept_rss
        status = "Error_In_Step_Computation" if outcome == "broken" else "Solve_Succeeded"
        by_exp = {t.name: rss / len(traces) for t in traces}
        return {"law": alt.law, "k": alt.k, "status": status, "iterations": 3} | {
            "rss_bar2": rss,
            "rss_ref_bar2": reference.kept_rss,
            "loeo_rss_bar2": rss,
            "loeo_bar2_by_experiment": by_exp,
        }

    monkeypatch.setattr(loop, "fit_alternative", stub)
    res = discover(tiny, settings=settings)
    (it,) = res.iterations
    (cand,) = it.candidates
    assert res.added == []
    assert calls == fitted
    assert alternative_note(cand.refit) == note
    assert it.decision.endswith("no effect claimed")


def _linear_residual_set(x, r, slices, names, ramps=None) -> ResidualSet:
    """A residual ``r`` linear in the parameters, Jacobian ``x``, every sample kept."""
    n = len(r)
    return ResidualSet(
        r=r,
        experiments=names,
        slices=slices,
        signals={},
        time_s=np.zeros(n),
        row_dt_s=0.01,
        n_period=1.0,
        keep=np.ones(n, dtype=bool),
        jacobian=x,
        ramps=ramps,
    )


def test_loeo_rss_equals_the_exact_held_out_error_of_a_linear_model():
    """For a residual linear in the parameters the block-deletion step is the exact refit."""
    rng = np.random.default_rng(4)
    x = rng.standard_normal((300, 3))
    y = x @ np.array([1.0, -2.0, 0.5]) + 0.1 * rng.standard_normal(300)
    theta0 = np.array([0.3, 0.1, -0.2])
    slices = [(0, 100), (100, 220), (220, 300)]
    res = _linear_residual_set(x, x @ theta0 - y, slices, ["a", "b", "c"])
    expected = 0.0
    for a, b in slices:
        others = np.r_[0:a, b:300]
        beta, *_ = np.linalg.lstsq(x[others], y[others], rcond=None)
        e = x[a:b] @ beta - y[a:b]
        expected += float(e @ e)
    assert loeo_rss(res) == pytest.approx(expected, rel=1e-9)
    assert loeo_errors(res).sum() == pytest.approx(expected, rel=1e-9)
    assert len(loeo_errors(res)) == len(res.slices)
    evidence = loeo_evidence(res)
    assert evidence["loeo_rss_bar2"] == loeo_rss(res)
    assert list(evidence["loeo_bar2_by_experiment"]) == ["a", "b", "c"]
    assert sum(evidence["loeo_bar2_by_experiment"].values()) == pytest.approx(expected)
    assert evidence["loro_rss_bar2"] is None  # no ramp labels
    one = ResidualSet(**{**res.__dict__, "slices": [(0, 300)], "experiments": ["a"]})
    assert loeo_rss(one) is None
    assert loeo_evidence(one)["loeo_bar2_by_experiment"] is None


def test_loeo_does_not_extrapolate_when_the_left_out_experiment_dominates_every_column():
    """Every parameter's sensitivity peaks in one experiment (a snap the model misplaces):
    without it the others determine nothing on the full data's scale, so the held-out
    step stays put and the held-out error is that experiment's own residual. A cut-off
    relative to the remaining experiments' largest singular value extrapolated instead."""
    rng = np.random.default_rng(6)
    x = 1e-9 * rng.standard_normal((300, 3))
    x[250:260] = 1e3 * rng.standard_normal((10, 3))  # the spike, in experiment "c"
    r = 0.1 * rng.standard_normal(300)
    r -= x @ np.linalg.lstsq(x, r, rcond=None)[0]  # at the fit's optimum
    slices = [(0, 100), (100, 220), (220, 300)]
    res = _linear_residual_set(x, r, slices, ["a", "b", "c"])
    errors = loeo_errors(res)
    own_c = float(r[220:300] @ r[220:300])
    assert errors[2] == pytest.approx(own_c, rel=1e-6)
    assert np.all(errors < 10 * float(r @ r))
    # the old operator: rcond relative to the remaining rows' own scale
    norms = np.linalg.norm(x, axis=0)
    others = np.r_[0:220]
    step, *_ = np.linalg.lstsq(x[others] / norms, -r[others], rcond=3e-2)
    e_old = r[220:300] + (x[220:300] / norms) @ step
    assert float(e_old @ e_old) > 1e6 * own_c


def test_leave_one_ramp_out_is_the_exact_held_out_error_of_a_linear_model_per_ramp():
    """Block deletion over a ramp's experiments together: for a residual linear in the
    parameters it is the exact refit on the other ramps; one experiment per ramp is
    leave-one-experiment-out, and then not reported twice."""
    rng = np.random.default_rng(5)
    x = rng.standard_normal((400, 3))
    y = x @ np.array([0.5, 1.0, -1.5]) + 0.1 * rng.standard_normal(400)
    slices = [(0, 100), (100, 200), (200, 320), (320, 400)]
    ramps = ["fast", "slow", "fast", "slow"]
    res = _linear_residual_set(x, -y, slices, ["f1", "s1", "f2", "s2"], ramps)
    expected = {}
    for ramp in ("fast", "slow"):
        held = np.zeros(400, dtype=bool)
        for (a, b), lab in zip(slices, ramps, strict=True):
            held[a:b] = lab == ramp
        beta, *_ = np.linalg.lstsq(x[~held], y[~held], rcond=None)
        e = x[held] @ beta - y[held]
        expected[ramp] = float(e @ e)
    got = loro_errors(res)
    assert got.keys() == expected.keys()
    for ramp in expected:
        assert got[ramp] == pytest.approx(expected[ramp], rel=1e-9)
    assert loeo_evidence(res)["loro_rss_bar2"] == pytest.approx(sum(expected.values()))
    single = ResidualSet(
        **{**res.__dict__, "slices": slices[:2], "experiments": ["f1", "s1"]}
        | {"r": res.r[:200], "keep": res.keep[:200], "jacobian": x[:200], "ramps": ramps[:2]}
    )
    assert loro_errors(single) is None


def test_augmented_hybrid_factory_builds_an_unfitted_model():
    from sklearn.exceptions import NotFittedError

    from clutchlab.validation.discover.variant import AugmentedHybrid, AugmentedPhysics, _build
    from clutchlab.validation.variants import VariantContext

    fit = FitSettings(progress=False, max_iter=7)
    model = _build(VariantContext(physics_settings=fit))
    assert isinstance(model, AugmentedHybrid)
    assert isinstance(model.physics, AugmentedPhysics)
    assert model.physics.settings.fit.max_iter == 7
    with pytest.raises(NotFittedError):
        model.predict(None)
    with pytest.raises(NotFittedError):
        AugmentedPhysics().predict(None)


def test_a_transport_delay_fit_frees_its_pade_delay_and_scores_over_it():
    from clutchlab.physics.effects import EFFECTS

    cls = EFFECTS["transport_delay"]
    assert cls.fit_parameters() == ("delay_d", "delay_d0")
    model = CircuitModel().with_effects("transport_delay")
    grid = scoring.nuisance_grid(model, "transport_delay")
    d0 = sorted(g["delay_d0"] for g in grid)
    spec = {p.name: p for p in model.parameters}["delay_d0"]
    # a delay 10 x the default is representable: the filter's own delay reaches it
    assert d0[0] < spec.default < d0[-1] and d0[-1] == pytest.approx(10 * spec.default)


@pytest.fixture(scope="module")
def scored(tiny):
    """The base model at its defaults on the tiny stand's training ramps, ready to score:
    training traces, model, parameters, fit settings, residual set, projector."""
    return _ready_to_score(tiny)


def _ready_to_score(dataset):
    """The base model at its defaults on ``dataset``'s fast and slow ramps, with the
    training residual, its free parameters' Jacobian and the projector away from them."""
    train = list(dataset.select(ramps=["fast", "slow"]))
    model = CircuitModel()
    params = model.default_params()
    fit = _settings().fit
    base = residual_set(residual_problem(model, params, FREE, train, fit), train, True)
    proj = Projector(base.jacobian[base.keep])
    return SimpleNamespace(train=train, model=model, params=params, fit=fit, base=base, proj=proj)


def test_an_effect_linear_in_its_strength_scores_the_same_at_zero_and_default(scored):
    # the sensor lag's output is exactly linear in its strength κ: linearizing at κ = 0
    # or at the default κ = 1 (from the residual there) must give the same estimate
    train, model, params, fit = scored.train, scored.model, scored.params, scored.fit
    base, proj = scored.base, scored.proj
    values = dict(params.values)
    zero = score_effect("sensor_lag", model, values, train, base, proj, fit)
    default = score_effect("sensor_lag", model, values, train, base, proj, fit, expansion="default")
    assert zero.status == default.status == "scored"
    assert (zero.probe, default.probe) == ("zero", "default")
    assert zero.nuisance == default.nuisance
    assert default.strength["slag_kappa"] == pytest.approx(zero.strength["slag_kappa"], abs=1e-6)
    assert default.share == pytest.approx(zero.share, rel=1e-6)
    assert zero.share > 0.0


def test_profile_points_scale_every_strength_along_its_default_within_the_bounds():
    mhys = CircuitModel().with_effects("vfs_magnetic_hysteresis")
    h = [p["mhys_H"] for p in profile_points(mhys, "vfs_magnetic_hysteresis")]
    assert h == pytest.approx([0.9, 3.0])  # 10 × 0.3 N clipped to the 3 N bound
    lag = CircuitModel().with_effects("sensor_lag")
    assert profile_points(lag, "sensor_lag") == [{"slag_kappa": 1.0}]  # κ = 1 is its bound
    drift = CircuitModel().with_effects("latch_threshold_drift")
    pts = profile_points(drift, "latch_threshold_drift")
    assert pts[-1] == {"ldrift_dp_on": 3.0, "ldrift_dp_off": -3.0}
    assert pts[0] == pytest.approx({"ldrift_dp_on": 1.5, "ldrift_dp_off": -1.2})


def test_the_profile_look_linearizes_at_its_best_point_and_counts_each_point(scored):
    # magnetic hysteresis: two profile points, one Gauss–Newton step from the best; the
    # statistic can only improve on the best point's (the step may stay put)
    train, model, params, fit = scored.train, scored.model, scored.params, scored.fit
    base, proj = scored.base, scored.proj
    values = dict(params.values)
    name = "vfs_magnetic_hysteresis"
    prof = score_effect(name, model, values, train, base, proj, fit, expansion="profile")
    assert prof.status == "scored" and prof.probe == "profile"
    assert prof.n_tests == 2 and prof.statistic >= 0.0
    assert 0.0 <= prof.strength["mhys_H"] <= 3.0
    best, rss_best, diverged = scoring._profile_best(
        model.with_effects(name), name, values, train, base.keep, proj, fit
    )
    assert diverged == [] and prof.diverged == []
    r0 = proj(base.r[base.keep])
    cand = model.with_effects(name)
    problem = residual_problem(cand, cand.params(**values, **best), ("mhys_H",), train, fit)
    try:
        e = proj(problem.evaluate(np.zeros(problem.n_z), False)["r"][base.keep])
    finally:
        problem.close()
    assert float(e @ e) == pytest.approx(rss_best, rel=1e-9)
    at_best = max(1.0 - rss_best / float(r0 @ r0), 0.0)
    assert prof.share >= at_best - 1e-9


def test_no_step_is_taken_from_a_profile_point_worse_than_the_fitted_model(scored, monkeypatch):
    train, model, params, fit = scored.train, scored.model, scored.params, scored.fit
    base, proj = scored.base, scored.proj
    rp = proj(base.r[base.keep])
    worse = float(rp @ rp) * 1.5
    monkeypatch.setattr(scoring, "_profile_best", lambda *a: ({"mhys_H": 3.0}, worse, []))

    def no_sensitivity(*a, **k):
        raise AssertionError("no sensitivity at a point worse than the fitted model")

    monkeypatch.setattr(scoring, "_sensitivity", no_sensitivity)
    out = score_effect(
        "vfs_magnetic_hysteresis",
        model,
        dict(params.values),
        train,
        base,
        proj,
        fit,
        expansion="profile",
    )
    assert out.status == "scored" and out.probe == "profile"
    assert out.statistic == 0.0 and out.share == 0.0 and out.p_value == 1.0
    assert not out.significant


@pytest.fixture(scope="module")
def hot(tmp_path_factory):
    """The tiny stand with a 70 Hz dither that is high at low current (shape C), ready to
    score (:func:`_ready_to_score`)."""
    config = StandConfig(
        builtin_effects=False, settings=(DitherSetting(70.0, "C"),), ramps=TINY_RAMPS, seed=3
    )
    out = tmp_path_factory.mktemp("discover_hot") / "stand"
    write_stand(out, config, progress=False, figure=False)
    return _ready_to_score(load_dataset(out))


def test_a_profile_point_where_the_integration_diverges_is_recorded_not_scored(hot):
    # thin oil: 30 K above the viscosity's reference temperature, exp(−0.1 · 30) = 0.05 of
    # the spools' damping; under a 70 Hz dither the fit's 2 ROS2 substeps per 1 kHz sample
    # blow up there (measured: the stand's 8 do not). Such points are reported as not
    # evaluated, and give no statistic.
    train, model, params, fit = hot.train, hot.model, hot.params, hot.fit
    assert fit.substeps == 2
    assert {round(float(np.mean(t.get("oil_temp_C", 40.0)))) for t in train} == {40}
    values = dict(params.values) | {"temp_T_ref": 10.0}
    name = "oil_temperature"
    out = score_effect(name, model, values, train, hot.base, hot.proj, fit, expansion="profile")
    assert out.status == "scored" and out.probe == "profile"
    assert {"temp_b": pytest.approx(0.1)} in out.diverged
    assert all(p in profile_points(model.with_effects(name), name) for p in out.diverged)
    assert out.statistic == 0.0 and not out.significant
    # at the fitted model's own temperature nothing diverges
    ref = dict(params.values) | {"temp_T_ref": 40.0}
    cool = score_effect(name, model, ref, train, hot.base, hot.proj, fit, expansion="profile")
    assert cool.diverged == []


def test_a_point_whose_error_exceeds_three_measured_spans_counts_as_diverged(monkeypatch):
    import clutchlab.validation.discover.residuals as residuals

    target = np.array([0.5, 4.0, 10.5])  # measured span 10 bar
    errors = {0.0: [0.1, -0.2, 0.3], 1.0: [0.1, 29.0, 0.0], 2.0: [0.1, -31.0, 0.0]}

    class Problem:
        def __init__(self):
            self.experiments = [SimpleNamespace(target=target)]
            self.shared, self.n_z = ("temp_b",), 1

        def start_workers(self, *a):
            pass

        def evaluate(self, z, jacobian):
            return {"ok": True, "r": np.array(errors[round(float(z[0]) * 10.0, 6)])}

        def close(self):
            pass

    monkeypatch.setattr(residuals, "residual_problem", lambda *a: Problem())
    cand = CircuitModel().with_effects("oil_temperature")
    scale = {p.name: p for p in cand.parameters}["temp_b"].scale
    assert scale == pytest.approx(0.1)  # z = strength / scale
    points = [{"temp_b": 0.0}, {"temp_b": 0.01}, {"temp_b": 0.02}]
    fit = SimpleNamespace(workers=1)
    rss = point_sums_of_squares(cand, {}, points, [], fit, np.ones(3, bool))
    assert rss[0] == pytest.approx(0.14) and rss[1] == pytest.approx(0.01 + 29.0**2)
    assert rss[2] == np.inf  # 31 bar > 3 × 10 bar


def test_the_summary_names_the_candidates_not_evaluated_where_the_model_diverged():
    from clutchlab.validation.discover import CandidateScore

    assert loop._diverged_note([CandidateScore("sensor_lag", 1)], 2) == ""
    oil = CandidateScore("oil_temperature", 1, diverged=[{"temp_b": 0.09}, {"temp_b": 0.1}])
    note = loop._diverged_note([CandidateScore("sensor_lag", 1), oil], 2)
    assert note.startswith("not evaluated where the model's integration diverged with 2 substeps")
    assert "oil_temperature at temp_b = 0.09, temp_b = 0.1" in note and "--substeps" in note


def test_a_second_expansion_keeps_the_larger_statistic_and_counts_both_tests(monkeypatch):
    from clutchlab.validation.discover import CandidateScore, score_candidates

    made = {
        ("a", "profile"): CandidateScore("a", 1, share=0.5, statistic=40.0, p_value=2e-10),
        ("b", "profile"): CandidateScore("b", 1, share=0.2, statistic=1.0, p_value=0.3),
    }

    hints = {}

    def fake(name, *args):
        hints[name] = args[-1]
        return made[(name, args[-2])]

    monkeypatch.setattr(scoring, "score_effect", fake)
    previous = [
        CandidateScore("a", 1, 0.01, 2.0, 0.15, nuisance={"eddy_tau": 9.0}, n_tests=4),
        CandidateScore("b", 1, share=0.3, statistic=30.0, p_value=1e-7),
    ]
    out = score_candidates(
        ["a", "b"],
        CircuitModel(),
        CircuitModel().default_params(),
        [],
        SimpleNamespace(jacobian=None),  # the fake scores need no residual
        None,
        expansion="profile",
        previous=previous,
    )
    by = {c.effect: c for c in out}
    # the profile look scores at the nuisance values of the first look
    assert hints == {"a": {"eddy_tau": 9.0}, "b": {}}
    assert by["a"].statistic == 40.0 and by["a"].n_tests == 5
    assert by["b"].statistic == 30.0 and by["b"].n_tests == 2
    assert by["a"].significant and by["b"].significant
    assert [c.effect for c in out] == ["a", "b"]


def test_a_candidate_already_refitted_keeps_its_score_in_the_second_look(monkeypatch):
    from clutchlab.validation.discover import CandidateScore, score_candidates

    def fake(name, *args):
        assert name == "b", "a refitted candidate must not be scored again"
        return CandidateScore("b", 1, share=0.2, statistic=25.0, p_value=5e-7)

    monkeypatch.setattr(scoring, "score_effect", fake)
    old_a = CandidateScore("a", 1, share=0.3, statistic=30.0, p_value=1e-7, n_tests=6)
    previous = [old_a, CandidateScore("b", 1, share=0.01, statistic=2.0, p_value=0.15)]
    out = score_candidates(
        ["a", "b"],
        CircuitModel(),
        CircuitModel().default_params(),
        [],
        SimpleNamespace(jacobian=None),
        None,
        expansion="profile",
        previous=previous,
        keep=frozenset({"a"}),
    )
    by = {c.effect: c for c in out}
    assert by["a"] is old_a and by["a"].n_tests == 6
    assert by["b"].statistic == 25.0 and by["b"].n_tests == 2
    # the family is still both candidates: level α/2 = 0.005, each divided by its tests
    assert by["a"].significant and by["b"].significant


def test_refits_are_ranked_by_one_information_criterion():
    # the outcome-blind sensor-lag stand: the true lag fits 8x better with fewer
    # parameters, whatever its two-fold held-out sum says
    td = {"rss_bar2": 2.393, "k": 2, "n_eff": 400.0, "loeo_rss_bar2": 5.7}
    sl = {"rss_bar2": 0.298, "k": 1, "n_eff": 300.0, "loeo_rss_bar2": 11.1}
    assert by_criterion([td, sl]) == [1, 0]
    # one sample size for all (the smallest): 1 % better fit for one more parameter
    # loses at n = 300 (300·ln 0.99 + ln 300 > 0), wins at n = 3000
    a = {"rss_bar2": 1.0, "k": 1, "n_eff": 300.0}
    b = {"rss_bar2": 0.99, "k": 2, "n_eff": 3000.0}
    assert by_criterion([b, a]) == [1, 0]
    assert by_criterion([b, {**a, "n_eff": 3000.0}]) == [0, 1]
    assert by_criterion([]) == []


def test_training_experiments_are_taken_at_the_fit_rate():
    """With a fit rate, the base fit, the screening refits and the evidence see the same
    1 kHz samples of an experiment logged at 5 kHz; the test ramps keep their own samples."""
    knots = ([0.0, 0.5, 1.0], [0.0, 900.0, 0.0])
    fast = make_trace(*knots, dt=2e-4, name="fast_a", ramp="fast")
    medium = make_trace(*knots, dt=2e-4, name="medium_a", ramp="medium")
    settings = DiscoverySettings(fit=FitSettings(fit_rate_Hz=1000.0))
    train, test = loop._split([fast, medium], settings)
    assert [t.sample_rate_Hz for t in train] == [pytest.approx(1000.0)]
    assert test == [medium]
    assert loop._split([fast, medium], DiscoverySettings())[0] == [fast]  # default: as logged
