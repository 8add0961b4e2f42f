"""The plant zoo: independent of the fit model, realistic, seeded, effects carried or refused."""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from realism import check_hysteresis_bands, check_latch, check_layout, check_linear_rise

from clutchlab.data import load_dataset
from clutchlab.errors import ModelError
from clutchlab.physics.effects import EFFECTS
from clutchlab.physics.stand import DEFAULT_SETTINGS
from clutchlab.physics.stand.plants import (
    LIBRARY_EFFECTS,
    PLANTS,
    PlantConfig,
    get_plant,
    run_plant,
)

PLANT_DIR = Path(__file__).parents[1] / "clutchlab" / "physics" / "stand" / "plants"
STAND_DIR = PLANT_DIR.parent
#: What the zoo may import from clutchlab: the bench, the data layer, errors, itself.
ALLOWED = (
    "clutchlab.physics.stand.plants",
    "clutchlab.physics.stand.environment",
    "clutchlab.physics.stand.scenarios",
    "clutchlab.data",
    "clutchlab.errors",
)
SETTINGS3 = DEFAULT_SETTINGS[::4]  # 30 Hz/A, 50 Hz/B, 70 Hz/C


def _imports(path: Path, package: str):
    """Absolute names of every module imported by the source file at ``path``."""
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            yield from (a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                yield ".".join([*base, node.module] if node.module else base)
            else:
                yield node.module


@pytest.mark.parametrize(
    "path",
    [*sorted(PLANT_DIR.glob("*.py")), STAND_DIR / "environment.py", STAND_DIR / "scenarios.py"],
    ids=lambda p: p.name,
)
def test_zoo_imports_nothing_of_the_fit_model(path):
    package = (
        "clutchlab.physics.stand.plants" if path.parent == PLANT_DIR else "clutchlab.physics.stand"
    )
    names = list(_imports(path, package))
    assert names, "the import reader found nothing: it is broken"
    for name in names:
        assert name != "casadi", f"{path.name} imports casadi"
        if name.startswith("clutchlab"):
            assert name.startswith(ALLOWED), f"{path.name} imports {name}"


def test_import_reader_catches_a_model_import(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text("from ...components.latch import LatchValve\nimport casadi\n")
    names = list(_imports(bad, "clutchlab.physics.stand.plants"))
    assert "clutchlab.physics.components.latch" in names and "casadi" in names


def test_at_least_four_plants_each_differing_in_two_laws():
    assert len(PLANTS) >= 4
    for spec in PLANTS.values():
        assert len(spec.laws) >= 2, spec.name
        assert len({p.name for p in spec.parameters}) == len(spec.parameters)


def test_library_effect_list_matches_the_library():
    assert set(LIBRARY_EFFECTS) == set(EFFECTS)


@pytest.mark.parametrize("name", list(PLANTS))
def test_every_library_effect_is_carried_or_refused_with_a_reason(name):
    spec = PLANTS[name]
    assert set(spec.effects) | set(spec.refused) == set(LIBRARY_EFFECTS)
    assert not set(spec.effects) & set(spec.refused)
    assert {"oil_temperature", "supply_droop", "sensor_lag"} <= set(spec.effects)
    for effect, reason in spec.refused.items():
        with pytest.raises(ModelError, match=reason[:20]):
            spec.check_effects([effect])
    names = {p.name for p in spec.parameters}
    for effect in spec.effects.values():
        assert set(effect.values) <= names


def test_unknown_plant_lists_the_known_ones():
    with pytest.raises(ModelError, match="saturating_lugre"):
        get_plant("no_such_plant")


@pytest.fixture(scope="module", params=list(PLANTS))
def plant_runs(request):
    """Three seeds of one plant, three dither settings × three ramps each."""
    return [
        run_plant(PlantConfig(request.param, settings=SETTINGS3, seed=s), progress=False)
        for s in (0, 1, 2)
    ]


def test_plant_passes_the_stands_realism_checks(plant_runs):
    for run in plant_runs:
        check_layout(run.dataset)
        check_hysteresis_bands(run.dataset)
        check_latch(run.dataset)
        check_linear_rise(run.dataset["slow_50Hz_B"])


def test_seeds_draw_different_units_within_their_ranges(plant_runs):
    spec = get_plant(plant_runs[0].config.plant)
    draws = [run.values for run in plant_runs]
    for p in spec.parameters:
        for v in draws:
            assert p.low <= v[p.name] <= p.high, p.name
    varied = [p.name for p in spec.parameters if p.high > p.low]
    assert all(len({d[n] for d in draws}) == 3 for n in varied)


def test_plant_is_reproducible_with_its_seed(plant_runs):
    run = plant_runs[0]
    again = run_plant(run.config, progress=False)
    for a, b in zip(run.dataset, again.dataset, strict=True):
        assert np.array_equal(a.get("clutch_pressure_bar"), b.get("clutch_pressure_bar"))


@pytest.mark.parametrize("name", list(PLANTS))
def test_effects_change_the_plant_and_only_their_own_parameters(name):
    from clutchlab.physics.stand import RAMPS

    cfg = dict(settings=SETTINGS3[:1], ramps=(RAMPS["fast"],), seed=3)
    base = run_plant(PlantConfig(name, **cfg), progress=False)
    for effect in ("oil_temperature", "supply_droop", "sensor_lag", "transport_delay"):
        run = run_plant(PlantConfig(name, effects=(effect,), **cfg), progress=False)
        own = set(get_plant(name).effects[effect].values)
        assert {k for k in run.values if run.values[k] != base.values[k]} == own, effect
        diff = run.true_pressure["fast_30Hz_A"] - base.true_pressure["fast_30Hz_A"]
        assert np.max(np.abs(diff)) > 0.05, effect


def test_oil_temperature_drift_moves_the_regulated_pressure():
    """With oil_temperature and a 40 → 85 °C drift the pressure deficit follows temperature."""
    from clutchlab.physics.stand import RAMPS

    cfg = dict(settings=SETTINGS3[:1], ramps=(RAMPS["slow"],), seed=0, temperature="drift")
    base = run_plant(PlantConfig("saturating_lugre", **cfg), progress=False)
    hot = run_plant(
        PlantConfig("saturating_lugre", effects=("oil_temperature",), **cfg), progress=False
    )
    trace = hot.dataset[0]
    temp = trace.get("oil_temp_C")
    assert temp[0] < 42 and temp[-1] > 83
    i = trace.get("current_cmd_mA")
    regulated = (i > 300) & (i < 700)
    d = (hot.true_pressure["slow_30Hz_A"] - base.true_pressure["slow_30Hz_A"])[regulated]
    assert np.corrcoef(d, temp[regulated])[0, 1] < -0.8


def _clutchlab(*args):
    return subprocess.run(
        [sys.executable, "-m", "clutchlab.cli", *args],
        capture_output=True,
        text=True,
        timeout=600,
    )


def test_cli_list_plants():
    res = _clutchlab("stand", "--list-plants")
    assert res.returncode == 0
    for name, spec in PLANTS.items():
        assert name in res.stdout and spec.summary in res.stdout


def test_cli_plant_writes_dataset_and_truth_beside(tmp_path):
    out = tmp_path / "zoo"
    res = _clutchlab(
        "stand", "--plant", "stribeck_supply", "--out", str(out), "--settings", "1", "--quiet",
        "--effects", "supply_droop", "--seed", "4",
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    ds = load_dataset(out)
    assert len(ds) == 3
    truth = json.loads((tmp_path / "zoo.truth.json").read_text())
    assert truth["plant"] == "stribeck_supply" and truth["seed"] == 4
    assert truth["effects"] == ["supply_droop"]
    assert truth["parameters"]["line_coupling"]["value"] > 0
    inside = " ".join(p.read_text(errors="ignore") for p in out.iterdir() if p.suffix != ".png")
    for word in ("stribeck", "line_coupling", "supply_droop", "truth", "lat_on"):
        assert word not in inside


def test_cli_plant_refuses_an_effect_with_the_reason_and_writes_nothing(tmp_path):
    out = tmp_path / "zoo"
    res = _clutchlab(
        "stand", "--plant", "quadratic_play", "--out", str(out), "--effects", "stribeck_friction"
    )
    assert res.returncode != 0
    assert "cannot carry 'stribeck_friction'" in res.stderr and "quasi-static" in res.stderr
    assert "Traceback" not in res.stderr
    assert not out.exists() and not (tmp_path / "zoo.truth.json").exists()
    res = _clutchlab("stand", "--plant", "nope", "--out", str(out))
    assert res.returncode != 0 and "saturating_lugre" in res.stderr
