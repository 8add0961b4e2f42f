"""The synthetic stand: realism of its output, truth kept outside the dataset, CLI."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from realism import check_hysteresis_bands, check_latch, check_layout, check_linear_rise

from clutchlab.data import load_dataset
from clutchlab.physics.stand import DitherSetting, RampProfile


def test_stand_layout_and_metadata(stand_run):
    assert len(stand_run.dataset) == 9
    check_layout(stand_run.dataset)


def test_sensor_noise_and_quantization(stand_run):
    trace = stand_run.dataset["slow_30Hz_A"]
    truth = stand_run.true_pressure["slow_30Hz_A"]
    p = trace.get("clutch_pressure_bar")
    hold = trace.time_s < 0.9  # 0 mA hold: truth is flat, what varies is noise
    assert np.std(p[hold] - truth[hold]) >= 0.02
    steps = np.diff(np.unique(p))
    assert np.min(steps) == pytest.approx(0.01, abs=1e-9)


def test_hysteresis_bands_above_600_mA_ordered_by_ramp_rate(stand_run):
    check_hysteresis_bands(stand_run.dataset)


def test_latch_on_above_latch_off_and_latched_pressure_is_line(stand_run):
    check_latch(stand_run.dataset)


def test_near_linear_regulated_rise(stand_run):
    check_linear_rise(stand_run.dataset["slow_50Hz_B"])


def test_stand_is_reproducible_with_its_seed():
    from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, run_stand

    cfg = dict(settings=(DitherSetting(50.0, "A"),), ramps=(RampProfile("fast", 1.0, 0.3),))
    a = run_stand(StandConfig(seed=7, **cfg), progress=False).dataset[0]
    b = run_stand(StandConfig(seed=7, **cfg), progress=False).dataset[0]
    c = run_stand(StandConfig(seed=8, **cfg), progress=False).dataset[0]
    p = "clutch_pressure_bar"
    assert np.array_equal(a.get(p), b.get(p))
    assert not np.array_equal(a.get(p), c.get(p))


def _clutchlab(*args, check=True):
    return subprocess.run(
        [sys.executable, "-m", "clutchlab.cli", *args],
        capture_output=True,
        text=True,
        check=check,
        timeout=600,
    )


def test_cli_stand_writes_dataset_png_and_truth_beside(tmp_path):
    out = tmp_path / "stand"
    res = _clutchlab("stand", "--out", str(out), "--settings", "3", "--quiet")
    assert "wrote 9 experiments" in res.stdout
    ds = load_dataset(out)
    assert len(ds) >= 9
    assert (out / "manifest.json").exists()
    png = out / "pressure_vs_current.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    truth = json.loads((tmp_path / "stand.truth.json").read_text())
    assert set(truth["effects"]) == {"stribeck_friction", "flow_force", "sensor_lag"}
    assert truth["parameters"]["reg_F_c"]["value"] != 1.0
    # Nothing inside the dataset folder reveals the truth.
    inside = " ".join(p.read_text(errors="ignore") for p in out.iterdir() if p.suffix != ".png")
    for word in ("stribeck", "flow_force", "sensor_lag", "reg_F_c", "truth"):
        assert word not in inside


def test_cli_stand_with_effects_and_unknown_effect(tmp_path):
    out = tmp_path / "fx"
    _clutchlab(
        "stand",
        "--out",
        str(out),
        "--settings",
        "1",
        "--quiet",
        "--no-builtin",
        "--effects",
        "sensor_lag,flow_force",
        "--seed",
        "3",
    )
    truth = json.loads((tmp_path / "fx.truth.json").read_text())
    assert truth["effects"] == ["sensor_lag", "flow_force"] and truth["seed"] == 3
    bad = _clutchlab(
        "stand", "--out", str(tmp_path / "bad"), "--effects", "sensor_lagg", check=False
    )
    assert bad.returncode != 0
    assert "unknown effect 'sensor_lagg'" in bad.stderr
    assert "transport_delay" in bad.stderr and "flow_force" in bad.stderr
    assert not (tmp_path / "bad").exists()


def test_cli_stand_writes_extra_ramp_rates(tmp_path):
    out = tmp_path / "rates"
    res = _clutchlab(
        "stand", "--out", str(out), "--settings", "1", "--ramps", "fast=2.5,r5=5", "--quiet"
    )
    assert "ramps: fast, r5" in res.stdout
    ds = load_dataset(out)
    assert sorted(ds.ramps) == ["fast", "r5"]
    r5 = ds.select(ramps=["r5"])[0]
    assert r5.duration_s == pytest.approx(3 * 1.0 + 2 * 5.0, abs=0.01)
    bad = _clutchlab("stand", "--out", str(tmp_path / "bad"), "--ramps", "fast=0,x", check=False)
    assert bad.returncode != 0 and "--ramps: 'fast=0'" in bad.stderr and "'x'" in bad.stderr
    assert not (tmp_path / "bad").exists()


@pytest.mark.parametrize("json_name", ["ds.truth.json", "ds/manifest.json", "ds"])
def test_cli_stand_json_may_not_be_the_truth_or_inside_the_dataset(tmp_path, capsys, json_name):
    """``--json DS.truth.json`` replaced the truth; ``--json DS/manifest.json`` broke DS."""
    from clutchlab.cli import main

    out = tmp_path / "ds"
    args = ["stand", "--out", str(out), "--settings", "1", "--ramps", "fast=0.5", "--quiet"]
    assert main([*args, "--json", str(tmp_path / json_name)]) == 2
    assert "this command writes (--out); write the summary elsewhere" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []  # refused before any work


def _no_simulation(*args, **kwargs):
    raise AssertionError("the stand ran before its output was checked")


@pytest.mark.parametrize("simulate", ["run_stand", "run_plant"])
def test_write_stand_refuses_its_output_before_the_simulation(tmp_path, monkeypatch, simulate):
    """A user's file in the way, or a ramp label that is no file name, was found only when
    the dataset was saved: after minutes of simulation."""
    from clutchlab.errors import DataError, OutputError
    from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, write_stand
    from clutchlab.physics.stand.plants import PlantConfig

    monkeypatch.setattr("clutchlab.physics.stand.stand.run_stand", _no_simulation)
    monkeypatch.setattr("clutchlab.physics.stand.plants.run_plant", _no_simulation)
    kind = (
        StandConfig if simulate == "run_stand" else lambda **kw: PlantConfig("quadratic_play", **kw)
    )
    settings = (DitherSetting(30.0, "A"),)
    theirs = tmp_path / "measured"
    theirs.mkdir()
    (theirs / "fast_30Hz_A.csv").write_text("time_s,current_mA\n")
    (theirs / "notes.txt").write_text("keep")
    config = kind(settings=settings, ramps=(RampProfile("fast", 1.0),))
    with pytest.raises(OutputError, match=r"would replace them.*: fast_30Hz_A\.csv$"):
        write_stand(theirs, config, overwrite=True, progress=False)
    assert (theirs / "fast_30Hz_A.csv").read_text() == "time_s,current_mA\n"
    config = kind(settings=settings, ramps=(RampProfile("a/b", 1.0),))
    with pytest.raises(DataError, match="cannot write the dataset") as err:
        write_stand(tmp_path / "new", config, progress=False)
    assert "'a/b_30Hz_A' is not a portable file name" in str(err.value)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["measured"]


def test_overview_draws_every_ramp_of_the_setting_in_a_colour_of_its_own():
    """``--ramps fast=2.5,r5=5,...`` drew r5 in fast's blue; a label with an underscore
    (``warm_up``) made the figure pick the wrong setting and drop the other ramps."""
    from matplotlib.colors import to_hex
    from synthetic import make_trace

    from clutchlab.data import Dataset, Trace
    from clutchlab.physics.stand import plot_pressure_vs_current

    def trace(label, freq=30.0):
        tr = make_trace([0, 0.2, 0.6], [0, 0, 1100], dither_Hz=freq, ramp=label)
        tr = tr.with_signals(clutch_pressure_bar=tr.get("current_cmd_mA") / 100.0)
        tr.meta |= {"dither_freq_Hz": freq, "dither_shape": "A"}
        return Trace(f"{label}_{freq:g}Hz_A", tr.signals, meta=tr.meta)

    labels = ["warm_up", "fast", "r5", "medium", "r20", "slow"]
    ds = Dataset([trace(label) for label in labels] + [trace("fast", 50.0)])
    lines = plot_pressure_vs_current(ds).axes[0].get_lines()
    # one ramp rate for all: alphabetical (see the test of the ramp order below)
    assert [line.get_label() for line in lines] == [f"{x} ({x}_30Hz_A)" for x in sorted(labels)]
    colours = [to_hex(line.get_color()) for line in lines]
    assert len(set(colours)) == len(labels), colours


def _ramp_trace(label: str, ramp_s: float, freq: float = 30.0):
    """A stand-like experiment: 0 → 1100 → 0 mA in ``ramp_s`` each way, 0.1 s holds."""
    from synthetic import make_trace

    from clutchlab.data import Trace

    h, r = 0.1, ramp_s
    knots = [0, h, h + r, 2 * h + r, 2 * h + 2 * r, 3 * h + 2 * r]
    tr = make_trace(knots, [0, 0, 1100, 1100, 0, 0], dither_Hz=freq, ramp=label)
    tr = tr.with_signals(clutch_pressure_bar=tr.get("current_cmd_mA") / 100.0)
    tr.meta |= {"dither_freq_Hz": freq, "dither_shape": "A"}
    return Trace(f"{label}_{freq:g}Hz_A", tr.signals, meta=tr.meta)


#: Ramp labels and their ramp times (s), in dataset order: neither alphabetical nor by rate.
RAMP_TIMES = {"slow": 1.6, "medium": 0.8, "r0": 0.2, "fast": 0.4, "other": 0.4}


def test_order_ramps_is_fastest_first_then_alphabetical():
    from clutchlab.physics.stand import order_ramps

    rates = {"fast": 440.0, "medium": 110.0, "slow": 27.5, "a": 110.0, "nan": float("nan")}
    labels = ["slow", "x", "medium", "nan", "fast", "a", "fast"]
    assert order_ramps(labels, rates) == ["fast", "a", "medium", "slow", "nan", "x"]
    assert order_ramps(["slow", "medium", "fast"], {}) == ["fast", "medium", "slow"]


def test_overview_lists_the_ramps_fastest_first():
    """The legend listed the ramps in dataset order, not by ramp rate."""
    from clutchlab.data import Dataset
    from clutchlab.physics.stand import plot_pressure_vs_current

    ds = Dataset([_ramp_trace(label, r) for label, r in RAMP_TIMES.items()])
    lines = plot_pressure_vs_current(ds).axes[0].get_lines()
    order = ["r0", "fast", "other", "medium", "slow"]  # fast and other: one rate, alphabetical
    assert [line.get_label() for line in lines] == [f"{x} ({x}_30Hz_A)" for x in order]


def test_cli_stand_lists_the_ramps_fastest_first(tmp_path, monkeypatch, capsys):
    """``clutchlab stand`` printed the ramps alphabetically (``fast, r0, slow``)."""
    from types import SimpleNamespace

    import clutchlab.physics.stand as stand
    from clutchlab.cli import main
    from clutchlab.data import Dataset

    def write(out, config, **kwargs):  # the dataset of config's ramps, without simulating
        traces = [_ramp_trace(r.label, r.ramp_s) for r in config.ramps]
        return SimpleNamespace(dataset=Dataset(traces))

    monkeypatch.setattr(stand, "write_stand", write)
    ramps = ",".join(f"{label}={r}" for label, r in RAMP_TIMES.items())
    out = tmp_path / "ds"
    assert main(["stand", "--out", str(out), "--settings", "1", "--ramps", ramps, "--quiet"]) == 0
    assert "(ramps: r0, fast, other, medium, slow)" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("config", "needle"),
    [
        # ZeroDivisionError / IndexError tracebacks before:
        ({"sample_rate_Hz": 0.0}, "sample_rate_Hz must be a finite number > 0, not 0.0"),
        ({"settings": ()}, "settings: at least one dither setting is needed"),
        ({"ramps": ()}, "ramps: at least one ramp is needed"),
        # silently written: data that fails `clutchlab data check`, noise of negative size
        ({"sample_rate_Hz": 300.0}, "300 Hz does not resolve a 70 Hz dither (at least 700 Hz"),
        ({"pressure_noise_bar": -0.1}, "noise pressure_bar must be a finite number ≥ 0"),
        ({"ramps": (RampProfile("fast", -1.0),)}, "'fast' needs ramp_s > 0 s"),
        ({"settings": (DitherSetting(50.0, "Z"),)}, "unknown dither shape 'Z'"),
    ],
)
def test_stand_config_lists_its_problems_before_any_work(tmp_path, config, needle):
    from clutchlab.errors import ModelError
    from clutchlab.physics.stand import StandConfig

    with pytest.raises(ModelError, match="invalid stand configuration") as err:
        StandConfig(**config)
    assert needle in str(err.value)


def test_an_override_the_stand_model_lacks_names_its_effect_or_a_close_name():
    """It said only "override of unknown parameter(s): sup_r, reg_Fc"."""
    from clutchlab.errors import ModelError
    from clutchlab.physics.stand import StandConfig

    with pytest.raises(ModelError, match="invalid stand overrides") as err:
        StandConfig(overrides={"sup_r": 1.0, "reg_Fc": 1.0}).truth_params()
    text = str(err.value)
    assert "sup_r: it belongs to the effect 'supply_droop'" in text
    assert "StandConfig(effects=('supply_droop',)" in text
    assert "reg_Fc: unknown parameter (did you mean 'reg_F_c'" in text
    truth = StandConfig(effects=("supply_droop",), overrides={"sup_r": 1.0}).truth_params()
    assert truth["sup_r"] == 1.0


def test_plant_refuses_a_waveform_it_cannot_make():
    """A plant drew a square dither as a sine, and wrote "square" in the manifest."""
    from clutchlab.errors import ModelError
    from clutchlab.physics.stand.plants import PlantConfig

    square = (DitherSetting(50.0, "A", "square"),)
    with pytest.raises(ModelError, match="waveform 'square' is not one of"):
        PlantConfig("quadratic_play", settings=square)
    with pytest.raises(ModelError, match="temperature must be 'levels' or 'drift'"):
        PlantConfig("quadratic_play", temperature="hot")


def test_plant_refuses_an_effect_named_twice():
    """``--effects sensor_lag,sensor_lag`` drew the effect twice (another unit than naming
    it once) and listed it twice in the truth file."""
    from clutchlab.errors import ModelError
    from clutchlab.physics.stand.plants import PlantConfig

    with pytest.raises(ModelError, match="effect\\(s\\) named twice: sensor_lag"):
        PlantConfig("quadratic_play", effects=("sensor_lag", "sensor_lag"))


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--settings", "0"], "--settings must be 1..9"),
        (["--ramps", "fast=0"], "--ramps: 'fast=0'"),
        (["--temperature", "drift"], "--temperature drift applies to the zoo's plants"),
        (["--plant", "quadratic_play", "--no-builtin"], "--no-builtin applies to the stand only"),
    ],
)
def test_cli_stand_usage_errors_exit_2_with_the_command_name(tmp_path, capsys, args, needle):
    """These printed a bare message and exited 1, unlike every other usage error (2)."""
    from clutchlab.cli import main

    with pytest.raises(SystemExit) as exc:
        main(["stand", "--out", str(tmp_path / "ds"), *args])
    assert exc.value.code == 2
    assert f"clutchlab stand: error: {needle}" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_list_plants_says_the_effects_are_optional(capsys):
    """``effects it carries: sensor_lag, ...`` read as if every run had them; a run has none
    unless --effects names them (its truth file says ``"effects": []``)."""
    from clutchlab.cli import main

    assert main(["stand", "--list-plants"]) == 0
    out = capsys.readouterr().out
    assert "effects it carries" not in out
    assert out.count("effects it can carry (--effects; none by default): sensor_lag") == 4


def test_cli_params_table_has_a_header_and_the_fit_scale(capsys):
    """The table had no column names and no scale, though the README sends readers to it for
    "a unit, a datasheet default, bounds and a scale"."""
    from clutchlab.cli import main

    assert main(["params"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split() == ["name", "default", "unit", "[lower,", "upper]", "fit", "scale",
                                "description"]  # fmt: skip
    rho = next(line for line in lines if line.startswith("fluid_rho"))
    assert rho.split()[:6] == ["fluid_rho", "850", "kg/m³", "[800,", "900]", "log"]


@pytest.mark.parametrize("out", [".", "..", "../here/.."])
def test_cli_stand_refuses_the_current_folder_before_any_work(tmp_path, monkeypatch, capsys, out):
    """``--out .`` was a ValueError traceback (truth_path of a path without a name);
    ``--out here/..`` failed with "Device or resource busy" after the simulation."""
    from clutchlab.cli import main
    from clutchlab.physics.stand import truth_path

    here = tmp_path / "here"
    here.mkdir()
    (here / "notes.txt").write_text("mine")
    monkeypatch.chdir(here)
    monkeypatch.setattr("clutchlab.physics.stand.stand.run_stand", _no_simulation)
    args = ["stand", "--out", out, "--overwrite", "--settings", "1", "--ramps", "fast=0.5"]
    assert main([*args, "--quiet"]) == 2
    assert "is the current folder or holds it; name a folder to create" in capsys.readouterr().err
    assert [p.name for p in here.iterdir()] == ["notes.txt"]
    assert truth_path(".") == tmp_path / "here.truth.json"


def test_write_stand_never_replaces_a_users_file_where_the_truth_goes(tmp_path, monkeypatch):
    """``--overwrite`` replaced any ``<out>.truth.json``, also one clutchlab did not write."""
    from clutchlab.errors import OutputError
    from clutchlab.physics.stand import StandConfig, write_stand

    theirs = tmp_path / "bench.truth.json"
    theirs.write_text('{"calibration": "rig 4, 2026-03-02"}')
    monkeypatch.setattr("clutchlab.physics.stand.stand.run_stand", _no_simulation)
    config = StandConfig(settings=(DitherSetting(30.0, "A"),), ramps=(RampProfile("fast", 0.5),))
    with pytest.raises(OutputError, match="is not a truth file clutchlab wrote"):
        write_stand(tmp_path / "bench", config, overwrite=True, progress=False)
    assert theirs.read_text() == '{"calibration": "rig 4, 2026-03-02"}'


def test_list_plants_writes_the_list_to_json(tmp_path, capsys):
    """``--list-plants --json X`` printed the list and wrote nothing to X."""
    from clutchlab.cli import main

    target = tmp_path / "plants.json"
    assert main(["stand", "--list-plants", "--json", str(target)]) == 0
    doc = json.loads(target.read_text())
    assert next(iter(doc)) == "stand" and "quadratic_play" in doc
    assert "sensor_lag" in doc["quadratic_play"]["effects"] and doc["quadratic_play"]["laws"]


@pytest.mark.parametrize(
    ("n", "expected"),
    [
        (1, ["30/A"]),
        (2, ["30/A", "50/B"]),
        (3, ["30/A", "50/A", "70/A"]),
        (4, ["30/A", "30/C", "50/B", "70/A"]),
        (5, ["30/A", "30/B", "30/C", "50/A", "50/B"]),
    ],
)
def test_cli_stand_settings_are_the_documented_ones(tmp_path, monkeypatch, n, expected):
    """What ``--settings N`` draws is what its help says, and stays so: the recorded zoo
    studies' datasets (``--settings 3``) must be drawn again the same way. (The code's
    comment promised 30/A, 50/B, 70/C for 3, which it never gave.)"""
    import clutchlab.physics.stand as stand
    from clutchlab.cli import build_parser, main

    seen = {}

    def fake_write_stand(out, config, **kwargs):
        seen["settings"] = config.settings
        raise KeyboardInterrupt  # stop before any work; main() returns 130

    monkeypatch.setattr(stand, "write_stand", fake_write_stand)
    assert main(["stand", "--out", str(tmp_path / "ds"), "--settings", str(n)]) == 130
    assert [f"{s.freq_Hz:.0f}/{s.shape}" for s in seen["settings"]] == expected
    helps = [a.help for a in build_parser()._subparsers._group_actions[0].choices["stand"]._actions]
    assert any("3 = 30, 50, 70 Hz with shape A" in (h or "") for h in helps)
