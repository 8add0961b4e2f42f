"""The discovery's wall-time budget (``DiscoverySettings.time_limit_s``) and the demo's use of it.

A refit starts only while budget is left, runs at most what is left, and a refit the budget
stopped is not judged: the discovery ends with the model it had, claims nothing, says so
(decision, summary, JSON, a FitWarning), and never calls the residual "unexplained".
"""

from __future__ import annotations

import json
import time
import warnings

import pytest
from test_discover import CANDIDATES, tiny, tiny_dir  # noqa: F401  (module fixtures)

import clutchlab.validation.demo as demo
import clutchlab.validation.discover.loop as loop
from clutchlab.cli import main
from clutchlab.errors import FitError, FitWarning
from clutchlab.physics import CircuitModel
from clutchlab.physics.fit import FitSettings, PhysicsFitter
from clutchlab.validation.discover import DiscoverySettings, discover
from clutchlab.validation.discover.deadline import (
    DiscoveryTimeLimit,
    capped_fit,
    check_budget,
    discovery_budget,
)
from clutchlab.validation.discover.refit import run_fit
from clutchlab.validation.report import summary_lines

FIT = FitSettings(progress=False, free=("reg_F0",), max_iter=3, workers=1)


def _settings(**kw) -> DiscoverySettings:
    return DiscoverySettings(fit=FIT, progress=False, **kw)


@pytest.fixture(scope="module")
def base_fit(tiny):  # noqa: F811
    train = list(tiny.select(ramps=["fast", "slow"]))
    with warnings.catch_warnings():  # 3 iterations: stopped at its limit, on purpose
        warnings.simplefilter("ignore", FitWarning)
        return PhysicsFitter(CircuitModel(), FIT).fit(train).result_


@pytest.mark.parametrize("bad", [0.0, -5.0, float("nan")])
def test_a_time_limit_that_is_not_a_positive_number_is_refused(bad):
    with pytest.raises(FitError, match="time_limit_s must be > 0"):
        _settings(time_limit_s=bad)


def test_without_a_budget_nothing_is_capped_or_stopped():
    fit, capped = capped_fit(FIT)
    assert fit is FIT and not capped
    check_budget("anything")  # no budget running: never raises


def test_a_budget_caps_the_time_limit_of_a_fit_and_stops_when_spent():
    with discovery_budget(30.0, time.perf_counter()):
        fit, capped = capped_fit(FIT)
        assert capped and 29.0 < fit.time_limit_s <= 30.0
        check_budget("a refit")  # budget left: no stop
    with discovery_budget(10.0, time.perf_counter() - 11.0):
        with pytest.raises(
            DiscoveryTimeLimit, match=r"time budget \(10 s\) was spent before a refit"
        ):
            check_budget("a refit")
    with discovery_budget(5000.0, time.perf_counter()):  # the fit's own limit binds
        fit, capped = capped_fit(FIT)
        assert fit is FIT and not capped


def test_a_refit_the_budget_stops_is_not_returned_as_a_result(tiny):  # noqa: F811
    """A refit cut short by the budget would be judged against complete ones: it raises."""
    train = list(tiny.select(ramps=["fast", "slow"]))
    settings = _settings(time_limit_s=0.05)
    fit = FitSettings(progress=False, free=("reg_F0", "vfs_K_m"), max_iter=200, workers=1)
    with discovery_budget(0.05, time.perf_counter()):
        with pytest.raises(DiscoveryTimeLimit, match="the refit with x"):
            run_fit(CircuitModel(), train, settings, fit.free, None, fit, what="the refit with x")


def test_a_spent_budget_ends_the_discovery_before_its_first_iteration(tiny, base_fit):  # noqa: F811
    settings = _settings(candidates=CANDIDATES, max_effects=1, time_limit_s=1e-3)
    with pytest.warns(FitWarning, match="time budget") as recorded:
        res = discover(tiny, settings=settings, baseline=base_fit)
    (it,) = res.iterations
    assert it.time_limited and res.time_limited and it.effect is None and res.added == []
    assert it.decision.startswith("stopped: the discovery's time budget (0.001 s)")
    assert (
        recorded[0]
        .message.args[0]
        .endswith(f"the model is its baseline fit ({base_fit.status}, not converged)")
    )
    assert "before iteration 0" in it.decision
    assert res.summary.startswith("no effect added; stopped:")
    assert "the rest of the search did not run" in res.summary
    assert not res.unexplained and res.signature == []
    doc = json.loads(res.to_json())
    assert doc["time_limited"] is True and doc["iterations"][0]["time_limited"] is True
    assert doc["settings"]["time_limit_s"] == 1e-3


def test_a_refit_stopped_by_the_budget_keeps_the_evidence_and_claims_nothing(
    tiny,  # noqa: F811
    base_fit,
    monkeypatch,
):
    """The candidate is scored and significant, its refit is stopped by the budget: not
    added, the evidence table kept, the decision names the refit that did not end."""

    real = loop.run_fit

    def out_of_time(model, train, settings, free, start, fit=None, *, what="", **kw):
        if "supply_droop" in model.effect_names:
            raise DiscoveryTimeLimit(what, 600.0)
        return real(model, train, settings, free, start, fit, what=what, **kw)

    monkeypatch.setattr(loop, "run_fit", out_of_time)
    settings = _settings(candidates=("supply_droop",), max_effects=1, time_limit_s=600.0)
    with pytest.warns(FitWarning, match="before the refit with supply_droop"):
        res = discover(tiny, settings=settings, baseline=base_fit)
    (it,) = res.iterations
    assert it.time_limited and it.effect is None and res.added == []
    (cand,) = it.candidates
    assert cand.significant  # scored as far as it got: the evidence is kept
    assert it.decision == (
        "stopped: the discovery's time budget (600 s) was spent before the refit with "
        "supply_droop; no effect claimed"
    )
    assert not res.unexplained


def test_the_augmented_hybrid_takes_its_budget_from_a_deadline():
    from clutchlab.validation.discover.variant import _build
    from clutchlab.validation.variants import VariantContext

    deadline = time.perf_counter() + 50.0
    options = {"augmented_hybrid": {"discovery_deadline": deadline}}
    model = _build(VariantContext(physics_settings=FIT, options=options))
    assert 45.0 < model.physics.settings.time_limit_s <= 50.0
    own = {"settings": _settings(time_limit_s=10.0), "discovery_deadline": deadline}
    model = _build(VariantContext(options={"augmented_hybrid": own}))
    assert model.physics.settings.time_limit_s == 10.0  # the smaller of the two
    late = {"discovery_deadline": time.perf_counter() - 100.0}
    model = _build(VariantContext(options={"augmented_hybrid": late}))
    assert model.physics.settings.time_limit_s == 1.0  # at least a second: it says so


class _Stop(Exception):
    pass


def test_the_demo_ends_its_discovery_a_reserve_before_its_budget(tmp_path, monkeypatch):
    seen = {}

    def capture(dataset, variants, **kw):
        seen.update(kw, variants=list(variants), now=time.perf_counter())
        raise _Stop

    monkeypatch.setattr(demo, "stand_data", lambda folder, progress, config: ([], True))
    monkeypatch.setattr(demo, "evaluate", capture)
    t0 = time.perf_counter()
    with pytest.raises(_Stop):
        demo.run_demo(tmp_path / "d", progress=False, variants=["hybrid", "augmented_hybrid"])
    deadline = seen["options"]["augmented_hybrid"]["discovery_deadline"]
    expected = demo.DEMO_BUDGET_S - demo.DEMO_RESERVE_S
    assert t0 + expected <= deadline <= seen["now"] + expected
    with pytest.raises(_Stop):
        demo.run_demo(tmp_path / "d", progress=False, variants=["physics_default"])
    assert seen["options"] == {}  # no discovery: nothing to limit
    with pytest.raises(_Stop):
        demo.run_demo(tmp_path / "d", progress=False, time_budget_s=None)
    assert seen["options"] == {}


def test_the_terminal_summary_says_the_discovery_stopped_at_its_limit():
    doc = {
        "variants": {"hybrid": {"rmse_bar": 0.03}, "augmented_hybrid": {"rmse_bar": 0.03}},
        "discovery": {"time_limited": True, "time_limit_s": 194.0},
    }
    lines = summary_lines(doc)
    assert any(
        line.startswith("augmented_hybrid: its discovery stopped at its time budget (194")
        for line in lines
    )
    doc["discovery"]["time_limited"] = False
    assert not any("time budget" in line for line in summary_lines(doc))


def test_cli_budget_ends_the_discovery_with_a_warning_and_exit_0(tiny_dir, tmp_path, capsys):  # noqa: F811
    out = tmp_path / "report"
    argv = ["discover", str(tiny_dir), "--out", str(out), "--json", str(tmp_path / "d.json")]
    argv += ["--free", "reg_F0", "--candidates", ",".join(CANDIDATES), "--max-iter", "3"]
    code = main([*argv, "--budget", "0.001", "--quiet"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "warning: discovery: stopped: the discovery's time budget (0.001 s)" in captured.err
    doc = json.loads((tmp_path / "d.json").read_text(encoding="utf-8"))
    assert doc["time_limited"] is True and doc["added"] == []
    assert (out / "report.html").is_file()
    with pytest.raises(SystemExit) as refused:  # checked before any work
        main([*argv, "--budget", "0", "--quiet"])
    assert refused.value.code == 2
