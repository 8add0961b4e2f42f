"""Input safety (issue 18, items 4, 8 and 12): nothing outside the dataset folder is read,
hostile CSVs fail fast and small, and the smaller defects each have a regression test."""

from __future__ import annotations

import json
import os
import sys
import time

import numpy as np
import pytest

from clutchlab.data import load_dataset, read_log, save_dataset
from clutchlab.data.convert import convert
from clutchlab.errors import DataError, FitError, ModelError
from clutchlab.physics.design.spec_parse import parse_spec
from clutchlab.physics.fit import FitSettings, PhysicsFitter
from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, run_stand

CANARY = "SECRET-CANARY-3141"


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    run = run_stand(
        StandConfig(
            settings=(DitherSetting(50.0, "B"),),
            ramps=(RampProfile("fast", 1.0, 0.2), RampProfile("medium", 2.0, 0.2)),
        ),
        progress=False,
    )
    return run.dataset


@pytest.fixture
def opened():
    """Every path opened while the test body runs (``open`` audit events)."""
    paths: list[str] = []
    active = [True]

    def hook(event, args):
        if active[0] and event == "open" and isinstance(args[0], str | bytes | os.PathLike):
            paths.append(os.fsdecode(args[0]))

    sys.addaudithook(hook)
    yield paths
    active[0] = False


def make_outside(tmp_path):
    """A canary log and a canary map outside the dataset folder."""
    outside = tmp_path / "outside"
    outside.mkdir()
    (outside / "secret.csv").write_text(f"time_s,{CANARY}\n0,1\n")
    (outside / "secret.toml").write_text(f'[signals]\ntime_s = "{CANARY}"\n')
    return outside


@pytest.mark.parametrize("key", ["file", "channel_map"])
@pytest.mark.parametrize("how", ["absolute", "dotdot", "symlink"])
def test_manifest_paths_out_of_the_folder_are_refused_unread(small, tmp_path, opened, key, how):
    outside = make_outside(tmp_path)
    root = save_dataset(small, tmp_path / "ds")
    target = outside / ("secret.csv" if key == "file" else "secret.toml")
    value = {
        "absolute": str(target),
        "dotdot": f"../outside/{target.name}",
        "symlink": "link" + target.suffix,
    }[how]
    if how == "symlink":
        (root / value).symlink_to(target)
    manifest = json.loads((root / "manifest.json").read_text())
    manifest["experiments"][0][key] = value
    (root / "manifest.json").write_text(json.dumps(manifest))
    opened.clear()  # from here on, nothing outside the dataset folder may be opened
    with pytest.raises(DataError) as exc:
        load_dataset(root)
    text = str(exc.value)
    assert "experiments[0]" in text and repr(key) in text
    assert CANARY not in text
    with pytest.raises(DataError):
        convert(root, tmp_path / "converted")
    assert not (tmp_path / "converted").exists()
    assert not [p for p in opened if os.path.realpath(p).startswith(str(outside))]


def test_fifo_and_folder_are_named_as_such_and_never_opened(small, tmp_path):
    root = save_dataset(small, tmp_path / "ds")
    os.mkfifo(root / "pipe.csv")
    (root / "dir.csv").mkdir()
    manifest = json.loads((root / "manifest.json").read_text())
    manifest["experiments"][0]["file"] = "pipe.csv"
    manifest["experiments"][1]["file"] = "dir.csv"
    (root / "manifest.json").write_text(json.dumps(manifest))
    t0 = time.perf_counter()
    with pytest.raises(DataError) as exc:
        load_dataset(root)
    assert time.perf_counter() - t0 < 10  # a FIFO opened for reading would block here
    text = str(exc.value)
    assert "'pipe.csv' is not a regular file (a FIFO)" in text
    assert "'dir.csv' is a folder, not a file" in text
    with pytest.raises(DataError, match="is not a regular file"):
        read_log(root / "pipe.csv")


def test_csv_with_200000_columns_fails_fast(tmp_path):
    path = tmp_path / "wide.csv"
    n = 200_000
    path.write_text(",".join(f"c{i}" for i in range(n)) + "\n" + ",".join(["1"] * n) + "\n")
    t0 = time.perf_counter()
    with pytest.raises(DataError, match="CLUTCHLAB_CSV_MAX"):
        read_log(path)
    assert time.perf_counter() - t0 < 5


def test_csv_header_followed_by_nul_bytes_is_refused_without_reading_it_whole(tmp_path):
    path = tmp_path / "nul.csv"
    path.write_bytes(b"time_s,current_mA,clutch_pressure_bar\n" + b"\0" * 50_000_000)
    with pytest.raises(DataError, match=r"NUL byte at byte 38 \(line 2\)"):
        read_log(path)


def test_effects_as_one_string_is_one_effect():
    assert "sensor_lag" in [e.name for e in StandConfig(effects="sensor_lag").model().effects]
    with pytest.raises(ModelError, match=r"unknown effect 'sensor_lagg'"):
        StandConfig(effects="sensor_lagg").model()
    doc = {
        "name": "x",
        "model": {"effects": "sensor_lag"},
        "variables": [{"name": "reg_F_c", "low": 0.5, "high": 1.5}],
        "sampling": {"method": "lhs", "n": 2},
    }
    spec = parse_spec(doc)
    assert spec.model.effects == ("sensor_lag",)


def test_with_effects_splits_a_comma_list_as_the_command_line_does():
    from clutchlab.physics import CircuitModel

    model = CircuitModel().with_effects("sensor_lag, transport_delay")
    assert model.effect_names == ("sensor_lag", "transport_delay")
    with pytest.raises(ModelError, match=r"unknown effect 'sensor_lagg'"):
        CircuitModel().with_effects("transport_delay,sensor_lagg")
    with pytest.raises(ModelError, match="switched on twice: sensor_lag"):
        CircuitModel().with_effects("sensor_lag", "sensor_lag , transport_delay")


def test_fit_refuses_a_requested_training_ramp_that_is_missing(small):
    fitter = PhysicsFitter(settings=FitSettings(train_ramps=("fast", "slow"), progress=False))
    with pytest.raises(FitError, match=r"training ramp\(s\) \['slow'\] not in the dataset"):
        fitter.fit(small)


def test_report_markdown_escapes_user_strings(small):
    from clutchlab.validation import evaluate
    from clutchlab.validation.report import jsonable, render_markdown

    ev = evaluate(small, ["physics_default"], train=["fast"], progress=False, command="x`y")
    doc = jsonable(ev.to_dict())
    doc["split"]["train_ramps"] = ["<img src=x onerror=alert(1)>|**bold**"]
    text = render_markdown(doc, [])
    assert "<img" not in text and "&lt;img" in text
    assert r"\|\*\*bold\*\*" in text
    assert "`` x`y ``" in text


def test_a_failing_residual_ml_import_is_not_hidden(small, monkeypatch):
    import importlib

    from clutchlab.validation.protocol import Protocol

    evaluate_module = importlib.import_module("clutchlab.validation.evaluate")

    import clutchlab

    monkeypatch.setitem(sys.modules, "clutchlab.residual_ml", None)
    monkeypatch.delattr(clutchlab, "residual_ml")
    protocol = Protocol(small, train=["fast"], test=["medium"])
    with pytest.raises(ImportError):
        evaluate_module._classifier_comparison(protocol, False, 0)


def test_reader_results_unchanged_for_good_files(small, tmp_path):
    root = save_dataset(small, tmp_path / "ds")
    back = load_dataset(root)
    np.testing.assert_allclose(
        back[0].get("clutch_pressure_bar"), small[0].get("clutch_pressure_bar"), atol=1e-8
    )
