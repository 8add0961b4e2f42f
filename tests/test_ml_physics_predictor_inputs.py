"""PhysicsPredictor: an effect name given alone is that effect; substeps are not truncated."""

from __future__ import annotations

import numpy as np
import pytest

from clutchlab.errors import ModelError
from clutchlab.residual_ml import PhysicsPredictor


def test_one_effect_name_alone_is_that_effect_not_its_letters():
    """PhysicsPredictor(effects="sensor_lag") was refused with "unknown effect 's'"."""
    one = PhysicsPredictor("sensor_lag", {"slag_tau": 2.0})
    assert one.effects == ("sensor_lag",)
    assert one == PhysicsPredictor(("sensor_lag",), {"slag_tau": 2.0})
    assert PhysicsPredictor("sensor_lag, flow_force").effects == ("sensor_lag", "flow_force")


@pytest.mark.parametrize("substeps", [2.7, 0, 65, True, "4"])
def test_substeps_that_are_not_a_step_count_are_refused(substeps):
    """substeps=2.7 was truncated to 2 without a word; 0 failed only at predict time."""
    with pytest.raises(ModelError, match=r"substeps .* is not an integer in 1\.\.64"):
        PhysicsPredictor(substeps=substeps)


def test_integer_substeps_are_kept():
    assert PhysicsPredictor(substeps=np.int64(2)).substeps == 2
    assert PhysicsPredictor().substeps == 4


def test_residual_ml_default_physics_is_a_deprecated_alias_of_the_datasheet_predictor():
    """Two public DefaultPhysics meant different things (a PhysicsPredictor factory here, the
    physics_default estimator in clutchlab.validation); the factory is now deprecated."""
    import clutchlab.residual_ml as rm
    from clutchlab import validation

    with pytest.warns(DeprecationWarning, match=r"use PhysicsPredictor\(\)"):
        old = rm.DefaultPhysics(substeps=2)
    assert old == PhysicsPredictor(substeps=2)
    assert "DefaultPhysics" not in rm.__all__
    assert "DefaultPhysics" in validation.__all__  # the variant keeps its name
