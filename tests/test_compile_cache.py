"""The compiled-code cache: a build started in the background is waited for, not repeated;
a failed build leaves nothing behind."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from clutchlab.physics import integrator
from clutchlab.physics.integrator import compile_function, compile_in_background


def _function(scale: float) -> ca.Function:
    x = ca.SX.sym("x", 3)
    return ca.Function("f", [x], [scale * ca.sin(x) + x**2])


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv("CLUTCHLAB_CACHE", str(tmp_path))
    return tmp_path


def test_a_background_build_is_awaited_and_loaded(cache):
    fn = _function(2.0)
    compile_in_background(fn, "bg_test")
    (lib,) = [p for p in integrator._BUILDS if p.parent == cache]
    build = integrator._BUILDS[lib]
    compile_in_background(fn, "bg_test")  # already being built: nothing new starts
    assert integrator._BUILDS[lib] is build
    compiled = compile_function(fn, "bg_test")
    assert lib not in integrator._BUILDS and lib.exists()
    assert isinstance(compiled, ca.Function)
    x = np.array([0.1, -0.4, 1.3])
    assert np.allclose(np.asarray(compiled(x)).ravel(), np.asarray(fn(x)).ravel())
    # one library in the cache, no source or partial file left
    assert [p.suffix for p in cache.iterdir()] == [".so"]
    compile_in_background(fn, "bg_test")  # cached: nothing starts
    assert lib not in integrator._BUILDS


def test_a_failed_background_build_leaves_nothing_and_the_call_reports_it(cache, monkeypatch):
    monkeypatch.setenv("CC", "false")  # a "compiler" that always fails
    fn = _function(3.0)
    compile_in_background(fn, "bg_fail")
    with pytest.warns(RuntimeWarning, match="C compilation failed"):
        assert compile_function(fn, "bg_fail") is None
    assert list(cache.iterdir()) == []


def test_the_fit_compiles_its_jacobian_code_before_its_workers_fork(cache, monkeypatch):
    """The staged start runs while the main stages' code compiles in the background, and
    each stage's code is in the cache before its worker processes fork (so they do not
    each compile it on first use)."""
    from clutchlab.errors import FitWarning
    from clutchlab.physics.fit import FitProblem, FitSettings, PhysicsFitter
    from clutchlab.physics.fit import fitter as fitter_module
    from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, run_stand

    data = run_stand(
        StandConfig(
            builtin_effects=False,
            settings=(DitherSetting(50.0, "A"), DitherSetting(70.0, "B")),
            ramps=(RampProfile("fast", 1.5, 0.3),),
            seed=3,
        ),
        progress=False,
    ).dataset
    started, at_fork = [], []
    ahead = fitter_module.compile_sensitivities_for

    def spy_ahead(model, traces, substeps, drive, nd, background=False):
        started.append((background, substeps, nd))
        ahead(model, traces, substeps, drive, nd, background)

    fork = FitProblem.start_workers

    def spy_fork(self, traces, workers):
        at_fork.append(sorted(p.name for p in cache.glob("clutchlab_sens_*.so")))
        fork(self, traces, workers)

    monkeypatch.setattr(fitter_module, "compile_sensitivities_for", spy_ahead)
    monkeypatch.setattr(FitProblem, "start_workers", spy_fork)
    settings = FitSettings(progress=False, train_ramps=("fast",), substeps=3, max_iter=2, workers=2)
    with pytest.warns(FitWarning, match="before converging"):  # max_iter=2: a short fit
        fitter = PhysicsFitter(settings=settings).fit(data)
    nd = len(fitter.result_.free)
    assert started and all(s == (True, 3, nd) for s in started)
    assert at_fork and all(any(f"_3_{nd}_" in n for n in names) for names in at_fork)
