"""Structure selection inside the training set.

BIC picks a flexible law only when the data need it. The two selections fit four small
models (about 20-40 s each on a quiet 2-core machine): marked slow.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from clutchlab.data import save_dataset
from clutchlab.errors import FitError, ModelError, OutputError
from clutchlab.physics import CircuitModel
from clutchlab.physics.fit import FitSettings, StructureSelector
from clutchlab.physics.fit.structure import (
    CandidateScore,
    StructureSelection,
    effective_sample_size,
    information_criterion,
    structure_effects,
)
from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, run_stand

#: Parameters the stand builds "as-built" but a default fit does not free: reset to the
#: datasheet so that the plain-model data are exactly the plain fit model's form.
_NOT_FREE_AS_BUILT = ("cacc_k", "fluid_beta")


def _small_stand(effects=(), overrides=None):
    defaults = CircuitModel().default_params()
    values = {n: defaults[n] for n in _NOT_FREE_AS_BUILT}
    values.update(overrides or {})
    config = StandConfig(
        builtin_effects=False,
        effects=effects,
        settings=(DitherSetting(50.0, "B"),),
        ramps=(RampProfile("fast", 2.0), RampProfile("medium", 3.0), RampProfile("slow", 5.0)),
        substeps=2,
        overrides=values,
        seed=5,
    )
    return run_stand(config, progress=False).dataset


SETTINGS = FitSettings(substeps=2, drive="command", progress=False, max_iter=25, time_limit_s=90.0)


@pytest.fixture(scope="module")
def kinked_choice():
    """Data whose VFS force curve has a step at 350 mA the tanh curve cannot take."""
    data = _small_stand(("vfs_force_monotone",), {"mspl_d2": 3.0, "mspl_w": 40.0})
    return StructureSelector(("plain", "force"), SETTINGS).fit(data)


@pytest.fixture(scope="module")
def plain_choice():
    return StructureSelector(("plain", "force"), SETTINGS).fit(_small_stand())


@pytest.mark.slow
def test_flexible_force_law_is_chosen_on_data_the_datasheet_form_cannot_express(kinked_choice):
    sel = kinked_choice.selection_
    scores = {c.name: c for c in sel.candidates}
    assert sel.chosen == "force" and sel.effects == ["vfs_force_monotone"]
    assert scores["force"].rmse_bar < 0.7 * scores["plain"].rmse_bar
    assert scores["force"].n_params == scores["plain"].n_params + 4
    assert kinked_choice.fitter_.model_.effect_names == ("vfs_force_monotone",)


@pytest.mark.slow
def test_plain_structure_is_chosen_on_data_of_the_plain_model(plain_choice):
    sel = plain_choice.selection_
    scores = {c.name: c for c in sel.candidates}
    assert sel.chosen == "plain" and sel.effects == []
    assert scores["plain"].bic < scores["force"].bic


@pytest.mark.slow
def test_choice_reports_training_scores_and_never_reads_the_test_ramp(kinked_choice, tmp_path):
    sel = kinked_choice.selection_
    assert sel.train and not [n for n in sel.train if n.startswith("medium")]
    path = tmp_path / "structure.json"
    sel.to_json(path)
    back = json.loads(path.read_text())
    assert back["chosen"] == "force" and back["n_eff"] <= back["n_periods"]
    assert {c["name"] for c in back["candidates"]} == {"plain", "force"}
    for c in back["candidates"]:
        assert math.isfinite(c["bic"]) and c["rmse_bar"] > 0 and c["wall_s"] > 0
    assert "force" in sel.table() and "*" in sel.table()


def test_effective_sample_size_follows_the_lag_one_correlation():
    rng = np.random.default_rng(0)
    white = rng.normal(size=4000)
    assert effective_sample_size([white]) == pytest.approx(4000, rel=0.08)
    ar = np.zeros(4000)
    for k in range(1, 4000):
        ar[k] = 0.9 * ar[k - 1] + rng.normal()
    assert effective_sample_size([ar]) == pytest.approx(4000 * 0.1 / 1.9, rel=0.3)
    assert effective_sample_size([white[:2000], white[2000:]]) == pytest.approx(
        effective_sample_size([white]), rel=0.05
    )


def test_information_criterion_trades_residual_against_parameters():
    n_eff = 400.0
    # 4 more parameters must buy mse by a factor exp(4 ln n / n) ≈ 1.062
    assert information_criterion(1.0, 12, n_eff) > information_criterion(1.0, 8, n_eff)
    assert information_criterion(0.9, 12, n_eff) < information_criterion(1.0, 8, n_eff)
    assert information_criterion(0.97, 12, n_eff) > information_criterion(1.0, 8, n_eff)


def test_bad_structure_requests_fail_loudly():
    with pytest.raises(ModelError, match="known structures"):
        structure_effects("spline9")
    with pytest.raises(FitError, match="free=None"):
        StructureSelector(("plain",), FitSettings(free=("vfs_K_m",))).fit([])


def test_select_structure_cli_names_the_known_structures_on_a_bad_request(tmp_path):
    config = StandConfig(
        builtin_effects=False,
        settings=(DitherSetting(50.0, "A"),),
        ramps=(RampProfile("fast", 1.0, 0.3), RampProfile("slow", 1.5, 0.3)),
        seed=4,
        substeps=2,
    )
    data = tmp_path / "stand"
    save_dataset(run_stand(config, progress=False).dataset, data)
    res = subprocess.run(
        [
            *(sys.executable, "-m", "clutchlab.cli", "select-structure", str(data)),
            *("--candidates", "plain,spline9", "--quiet"),
        ],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 2
    assert "unknown structure 'spline9'" in res.stderr and "flex" in res.stderr


def test_the_choice_is_written_atomically(tmp_path):
    """The summary replaces an earlier file in one step, refuses a folder at its path with a
    clear error, and leaves no temporary file behind."""
    sel = StructureSelection(
        chosen="plain",
        effects=[],
        criterion="BIC",
        n_periods=100,
        n_eff=40.0,
        candidates=[CandidateScore("plain", [], 8, 0.05, -10.0, "ok", True, 1.0)],
        train=["fast_50Hz_A"],
        wall_s=1.0,
    )
    path = tmp_path / "structure.json"
    path.write_text("an earlier choice\n")
    text = sel.to_json(path)
    assert path.read_text() == text + "\n" and json.loads(text)["chosen"] == "plain"
    with pytest.raises(OutputError, match="is a folder"):
        sel.to_json(tmp_path)
    assert [p.name for p in tmp_path.iterdir()] == ["structure.json"]
