"""The evaluation report: fit convergence as the fit reported it, one colour per variant."""

from __future__ import annotations

from types import SimpleNamespace

import pytest

import clutchlab.physics.fit as fit_pkg
from clutchlab.validation.variants import FittedPhysics


class _StoppedFitter:
    """A fit that stops at its iteration limit: returns its best iterate, not converged."""

    def __init__(self, model=None, settings=None):
        pass

    def fit(self, traces):
        self.result_ = SimpleNamespace(
            success=False,
            status="Maximum_Iterations_Exceeded",
            cost_history=[2.0, 1.0],
            values={"reg_F0": -1.6},
            free=["reg_F0"],
            train=[t.name for t in traces],
            wall_s=9.0,
        )
        return self


@pytest.mark.parametrize("success", [False, True])
def test_a_fit_returned_at_its_iteration_limit_is_not_reported_converged(
    monkeypatch, fast_ramp_trace, success
):
    class Fitter(_StoppedFitter):
        def fit(self, traces):
            super().fit(traces)
            self.result_.success = success
            return self

    monkeypatch.setattr(fit_pkg, "PhysicsFitter", Fitter)
    model = FittedPhysics().fit([fast_ramp_trace])
    assert model.converged_ is success


def test_every_variant_has_its_own_colour_in_every_figure():
    """A variant without a fixed colour took the k-th of the cycle, k its place in the
    figure: paper_faithful was drawn in hybrid's purple in the uncertainty figure and in
    pink in the residual figure."""
    from clutchlab.validation.figures import VARIANT_COLORS
    from clutchlab.validation.variants import variant_names

    names = [*variant_names(), "physics_fmu", "measured"]
    assert set(names) <= set(VARIANT_COLORS)
    colours = [VARIANT_COLORS[n] for n in names]
    assert len(set(colours)) == len(colours)


@pytest.mark.parametrize("converged", [False, True])
def test_the_terminal_summary_says_when_the_physics_fit_did_not_converge(converged):
    from clutchlab.validation.report import summary_lines

    doc = {
        "variants": {"physics_default": {"rmse_bar": 0.41}, "physics_fitted": {"rmse_bar": 0.42}},
        "details": {},
        "physics_fit": {"status": "not run", "converged": converged, "iterations": 0},
    }
    lines = summary_lines(doc)
    said = [line for line in lines if "NOT converge" in line]
    assert len(said) == (0 if converged else 1)
    if not converged:
        assert "(not run, 0 iterations)" in said[0]


def test_the_fitted_parameter_table_says_what_each_parameter_is():
    """The report's table gave ``vfs_K_m … N/A`` with no word of what it is (N/A reads as
    "not applicable"; it is newton per ampere), and ``vfs_d_orf`` without its meaning."""
    from clutchlab.physics import CircuitModel
    from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, run_stand
    from clutchlab.validation import evaluate
    from clutchlab.validation.evaluate import Evaluation
    from clutchlab.validation.report import jsonable, render_html, render_markdown

    res = SimpleNamespace(
        model=CircuitModel,
        free=["vfs_K_m", "vfs_d_orf"],
        values={"vfs_K_m": 14.5, "vfs_d_orf": 0.39},
        std_errors={"vfs_K_m": 0.002, "vfs_d_orf": 4e-5},
        units={"vfs_K_m": "N/A", "vfs_d_orf": "mm"},
        unidentifiable=(),
        status="Solve_Succeeded",
        success=True,
        iterations=7,
        wall_s=50.0,
        effects=(),
        per_experiment={},
    )
    ev = SimpleNamespace(models={"physics_fitted": SimpleNamespace(result_=res)})
    fit = Evaluation.physics_fit(ev)
    specs = {p.name: p for p in CircuitModel().parameters}
    assert fit["parameters"]["vfs_K_m"]["description"] == specs["vfs_K_m"].description
    assert "newton per ampere" in specs["vfs_K_m"].description
    run = run_stand(
        StandConfig(
            settings=(DitherSetting(50.0, "B"),),
            ramps=(RampProfile("fast", 1.0, 0.2), RampProfile("medium", 2.0, 0.2)),
        ),
        progress=False,
    )
    evaluated = evaluate(run.dataset, ["physics_default"], train=["fast"], progress=False)
    doc = jsonable(evaluated.to_dict()) | {"physics_fit": jsonable(fit)}
    for text in (render_markdown(doc, []), render_html(doc, [])):
        assert "meaning" in text and specs["vfs_d_orf"].description in text
    # a metrics file written before the meaning was recorded still renders
    for p in fit["parameters"].values():
        del p["description"]
    assert "vfs_K_m" in render_markdown(doc, [])
