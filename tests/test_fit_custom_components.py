"""A fit of a model with custom components is not saved as if it were the base circuit."""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from fit_support import synthetic_fit

from clutchlab.errors import ModelError
from clutchlab.physics import CircuitModel, default_components
from clutchlab.physics.components import PressureSensor
from clutchlab.physics.fit import PhysicsFitter
from clutchlab.residual_ml import PhysicsPredictor, persist


class MySensor(PressureSensor):
    """A user's sensor component (same parameters, a law of its own in real use)."""


def _fitted(model: CircuitModel) -> PhysicsFitter:
    params = model.default_params()
    result = replace(
        synthetic_fit(effects=model.effect_names, train=["fast_50Hz_B"]),
        free=["reg_F_c"],
        std_errors={"reg_F_c": 0.01},
        status="Solve_Succeeded",
    )
    fitter = PhysicsFitter(model)
    fitter.result_, fitter.model_, fitter.params_ = result, model, params
    return fitter


def test_custom_components_are_refused_on_save_naming_them(tmp_path):
    """save() wrote effects and values only, and load() rebuilt the base circuit: the
    user's component was silently replaced by clutchlab's."""
    custom = CircuitModel(components=(*default_components()[:-1], MySensor()))
    assert custom.custom_components() == ["8: MySensor"]
    fitter = _fitted(custom)
    with pytest.raises(ModelError, match=r"components other than the base circuit's \(8: MySe"):
        fitter.save(tmp_path / "fit.json")
    assert not (tmp_path / "fit.json").exists()
    with pytest.raises(ModelError, match="MySensor"):
        PhysicsPredictor.from_fitter(fitter)
    # a hybrid's physics is saved as a PhysicsPredictor: a fitted PhysicsFitter, or any
    # object holding a fitted model and values (the discovery's augmented physics)
    with pytest.raises(ModelError, match="MySensor"):
        persist._as_predictor(fitter)
    with pytest.raises(ModelError, match="MySensor"):
        persist._as_predictor(SimpleNamespace(model_=custom, params_=fitter.params_))


def test_the_base_circuit_saves_and_loads_as_before(tmp_path):
    model = CircuitModel().with_effects("sensor_lag")
    assert model.custom_components() == []
    fitter = _fitted(model)
    fitter.save(tmp_path / "fit.json")
    back = PhysicsFitter.load(tmp_path / "fit.json")
    assert back.model_.effect_names == ("sensor_lag",)
    np.testing.assert_array_equal(back.params_.vector(), fitter.params_.vector())
