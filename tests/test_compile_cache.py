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
