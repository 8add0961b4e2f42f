"""The compile cache's source keys: a cached library loads without building its code, and
nothing stale or broken is ever loaded."""

from __future__ import annotations

import importlib.util
import textwrap

import numpy as np
import pytest

from clutchlab.physics import integrator, source_key
from clutchlab.physics.fit import sensitivity
from clutchlab.physics.model import CircuitModel
from clutchlab.physics.source_key import code_source_key

#: The per-process caches of generated functions (taken before any test patches them).
_REMEMBERED = (integrator.chunk_function, sensitivity.sensitivity_chunk, sensitivity._mapped)


@pytest.fixture()
def cache(tmp_path, monkeypatch):
    """An empty compile cache, and no function remembered by this process."""
    monkeypatch.setenv("CLUTCHLAB_CACHE", str(tmp_path))
    for fn in _REMEMBERED:
        fn.cache_clear()
    yield tmp_path
    for fn in _REMEMBERED:
        fn.cache_clear()


def _forbid_building(monkeypatch):
    def fail(*args, **kwargs):
        raise AssertionError("the code was built although its library is recorded")

    monkeypatch.setattr(integrator, "sample_step_function", fail)
    monkeypatch.setattr(integrator, "_generate", fail)
    monkeypatch.setattr(sensitivity, "_mapped", fail)


def _chunk_inputs(model: CircuitModel, chunk: int):
    rng = np.random.default_rng(0)
    fns = model.functions("measured")
    x0 = np.array([s.initial for s in fns.states], dtype=float)
    nu = fns.u_sym.shape[0]
    u0 = np.abs(rng.normal(size=(nu, chunk)))
    return x0, u0, u0 * 1.01, np.full((1, chunk), 1e-3), model.default_params().vector()


def test_a_recorded_library_loads_without_building_and_gives_the_same_numbers(cache, monkeypatch):
    model = CircuitModel()
    first = integrator.chunk_function(model, "measured", 1, 4, "auto")
    assert list(cache.glob("*.src")), "the library was not recorded under its source key"
    args = _chunk_inputs(model, 4)
    want = [np.asarray(v) for v in first(*args)]

    integrator.chunk_function.cache_clear()
    _forbid_building(monkeypatch)
    again = integrator.chunk_function(model, "measured", 1, 4, "auto")
    got = [np.asarray(v) for v in again(*args)]
    assert all(np.array_equal(a, b) for a, b in zip(want, got, strict=True))


def test_the_sensitivity_loop_is_recorded_and_loaded_likewise(cache, monkeypatch):
    model = CircuitModel()
    first = sensitivity.sensitivity_chunk(model, "measured", 1, 1, 2)
    sensitivity.sensitivity_chunk.cache_clear()
    # builds an earlier test left running in this process (a fit's compile-ahead on an
    # empty cache) are not this call's: it must start none of its own
    before = set(integrator._BUILDS)
    sensitivity.compile_sensitivities_in_background(model, "measured", 1, 1, 2)  # no-op now
    assert set(integrator._BUILDS) <= before
    _forbid_building(monkeypatch)
    again = sensitivity.sensitivity_chunk(model, "measured", 1, 1, 2)
    assert again.name() == first.name()
    assert again.n_in() == first.n_in() and again.n_out() == first.n_out()


def test_a_record_of_a_missing_or_broken_library_is_not_loaded(cache):
    model = CircuitModel()
    name, tag = "chunk_4", f"clutchlab_{model.key}_measured_1"
    key = code_source_key(model, name, tag, "-O3")
    integrator.chunk_function(model, "measured", 1, 4, "auto")
    alias = cache / f"{tag}_{key}.src"
    assert alias.is_file()
    lib = cache / alias.read_text(encoding="utf-8").strip()

    # a broken library (never written over the loaded one: the cache only renames new
    # files into place) is not loaded, and raises nothing
    broken = cache / f"{tag}_0000000000000000.so"
    broken.write_bytes(b"not a shared library")
    alias.write_text(broken.name + "\n", encoding="utf-8")
    assert integrator.cached_by_source(name, tag, key) is None
    broken.unlink()  # gone: not loaded; the next call finds the code's library and records it
    assert integrator.recorded_library(tag, key) is None
    integrator.chunk_function.cache_clear()
    integrator.chunk_function(model, "measured", 1, 4, "auto")
    assert integrator.recorded_library(tag, key) == lib


def test_the_key_follows_the_structure_the_package_source_and_a_users_own_classes(
    tmp_path, monkeypatch
):
    base, droop = CircuitModel(), CircuitModel().with_effects("supply_droop")
    key = code_source_key(base, "chunk_4", "t", "-O3")
    assert key == code_source_key(CircuitModel(), "chunk_4", "t", "-O3")
    assert key != code_source_key(droop, "chunk_4", "t", "-O3")
    assert key != code_source_key(base, "chunk_8", "t", "-O3")
    assert key != code_source_key(base, "chunk_4", "t", "-O1")

    # any edit of the package's source gives new keys
    monkeypatch.setattr(source_key, "package_source_digest", lambda: "edited")
    assert key != code_source_key(base, "chunk_4", "t", "-O3")
    monkeypatch.undo()

    # so does an edit of an effect class that lives outside the package
    path = tmp_path / "my_effect.py"

    def user_model(gain: float) -> CircuitModel:
        path.write_text(
            textwrap.dedent(
                f"""
                from clutchlab.physics.effects.base import Effect

                class MyEffect(Effect):
                    name = "my_effect"
                    description = "a user's own"
                    signature = "none"
                    PARAMETERS = ()
                    STRENGTH = ()

                    def apply(self, asm):
                        asm.wrap("p_reg_pilot", lambda a, prev: {gain} * prev)
                """
            )
        )
        spec = importlib.util.spec_from_file_location("my_effect", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return CircuitModel().with_effects(module.MyEffect())

    one, two = user_model(1.0), user_model(1.01)
    assert one.key == two.key  # the structure's name alone cannot tell them apart
    assert code_source_key(one, "c", "t", "-O3") != code_source_key(two, "c", "t", "-O3")
