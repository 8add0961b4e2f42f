"""Notebook reprs of the physics objects: short, and saying what matters (no walls of
numbers, no <object at 0x...>)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from fit_support import synthetic_fit

from clutchlab.physics import CircuitModel, drive_trace, knot_profile, simulate
from clutchlab.physics.fit import FitSettings, PhysicsFitter

MODEL = CircuitModel().with_effects("sensor_lag")


def test_a_parameter_set_names_its_size_and_what_differs_from_the_defaults():
    """The dataclass repr printed every Parameter (about 9000 characters)."""
    params = MODEL.default_params()
    assert repr(params) == "ParameterSet(52 parameters, all at their datasheet defaults)"
    text = repr(params.replace(reg_F_c=1.2, slag_tau=3.0))
    assert text == "ParameterSet(52 parameters; changed: reg_F_c=1.2 N, slag_tau=3 ms)"
    many = params.replace(**{p.name: p.upper for p in MODEL.parameters[:20]})
    assert "… 8 more (see .changed())" in repr(many) and len(repr(many)) < 500


def test_a_model_names_its_effects_and_components_not_their_addresses():
    text = repr(MODEL)
    assert "object at 0x" not in text
    assert "effects=('sensor_lag',)" in text and "latch" in text and len(text) < 200


def test_a_simulation_result_summarises_instead_of_printing_its_arrays():
    t, i = knot_profile([0.0, 0.2, 0.2, 0.5], [0.0, 0.0, 600.0, 600.0])
    res = simulate(MODEL, MODEL.default_params(), drive_trace(t, i, name="step"))
    text = repr(res)
    assert text.startswith("SimulationResult(trace='step', 501 samples, 0–0.5 s")
    assert "clutch_pressure_bar" in text and "array(" not in text and len(text) < 400
    assert np.isfinite(res.pressure_bar).all()


def test_fit_objects_say_what_they_are_in_a_line():
    settings = FitSettings(time_limit_s=40, train_ramps="fast")
    assert repr(settings) == "FitSettings(train_ramps=('fast',), time_limit_s=40)"
    assert repr(FitSettings()) == "FitSettings()"
    fitter = PhysicsFitter(MODEL, settings)
    assert repr(fitter) == f"PhysicsFitter(model={MODEL!r}, settings={settings!r})"
    assert repr(PhysicsFitter()) == "PhysicsFitter()"
    result = replace(
        synthetic_fit(train=["fast_50Hz_A", "fast_50Hz_B"]),
        free=["reg_F_c"],
        cost_history=list(np.linspace(1.0, 0.1, 500)),
        status="Solve_Succeeded",
        iterations=12,
        wall_s=3.25,
    )
    text = repr(result)
    assert "status='Solve_Succeeded'" in text and "free=['reg_F_c']" in text
    assert "train=2 experiment(s)" in text and "cost_history" not in text and len(text) < 300
