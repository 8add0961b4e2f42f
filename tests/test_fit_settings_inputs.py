"""FitSettings: a name given alone is one name, and a malformed bound is named at once."""

from __future__ import annotations

import pytest

from clutchlab.errors import FitError
from clutchlab.physics import CircuitModel
from clutchlab.physics.fit import FitSettings, resolve_free


def test_one_name_alone_is_one_name_not_its_characters():
    """FitSettings(free="reg_F_c") was iterated letter by letter: the fit refused "unknown
    parameter(s) r, e, g, _, F, _, c", and train_ramps="fast" asked for ramps f, a, s, t."""
    s = FitSettings(free="reg_F_c", per_experiment="reg_F_c", train_ramps="fast")
    assert s.free == ("reg_F_c",) and s.per_experiment == ("reg_F_c",)
    assert s.train_ramps == ("fast",)
    assert resolve_free(CircuitModel(), s) == ("reg_F_c",)
    assert FitSettings(free=["reg_F_c", "reg_F0"]).free == ("reg_F_c", "reg_F0")
    assert FitSettings().free is None


def test_a_name_list_of_other_things_is_refused_naming_the_setting():
    with pytest.raises(FitError, match=r"free: 3 not a name") as info:
        FitSettings(free=("reg_F_c", 3), train_ramps=5)
    assert "train_ramps must be a name or a sequence of names, not 5" in str(info.value)


@pytest.mark.parametrize("pair", [(0.5,), (0.5, 2.0, 3.0), "ab", (0.5, float("nan")), 1.0])
def test_a_malformed_bound_is_named_not_a_bare_unpacking_error(pair):
    """bounds={"reg_F_c": (0.5,)} got through to the fit, which failed with a bare
    ValueError 'not enough values to unpack (expected 2, got 1)'."""
    with pytest.raises(FitError, match=r"bounds\['reg_F_c'\] must be \(lower, upper\)"):
        FitSettings(free=("reg_F_c",), bounds={"reg_F_c": pair})


def test_bounds_must_be_a_mapping():
    with pytest.raises(FitError, match="bounds must be a dict"):
        FitSettings(bounds=[("reg_F_c", 0.1, 1.0)])
    assert FitSettings(bounds={"reg_F_c": (0.1, 1.0)}).bounds == {"reg_F_c": (0.1, 1.0)}


OWNED = [("max_iter", "max_iter"), ("max_wall_time", "time_limit_s"), ("tol", "tol")]


@pytest.mark.parametrize(("option", "field"), OWNED)
def test_an_ipopt_option_a_setting_owns_is_refused_naming_the_setting(option, field):
    """ipopt_options={"max_wall_time": 3} silently overrode time_limit_s in every stage (and
    max_iter the refinement's own few iterations)."""
    said = rf"ipopt_options\['{option}'\] is set by FitSettings\.{field}"
    with pytest.raises(FitError, match=said):
        FitSettings(ipopt_options={option: 3})
    assert FitSettings(ipopt_options={"acceptable_iter": 0}).ipopt_options == {"acceptable_iter": 0}
    with pytest.raises(FitError, match="ipopt_options must be a dict"):
        FitSettings(ipopt_options=[("acceptable_iter", 0)])
