"""``clutchlab data check`` / ``clutchlab data convert`` through a subprocess; atomic convert."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from clutchlab.data import (
    FORMATS,
    Dataset,
    FileFormat,
    Trace,
    dither_period_samples,
    load_dataset,
    save_dataset,
)
from clutchlab.data.convert import convert
from clutchlab.errors import DataError
from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, run_stand


def cli(*args, cwd=None):
    return subprocess.run(
        [sys.executable, "-m", "clutchlab.cli", "data", *map(str, args)],
        capture_output=True,
        text=True,
        cwd=cwd,
    )


@pytest.fixture(scope="module")
def stand_ds(tmp_path_factory):
    run = run_stand(
        StandConfig(settings=(DitherSetting(50.0, "B"),), ramps=(RampProfile("medium", 10.0),)),
        progress=False,
    )
    return save_dataset(run.dataset, tmp_path_factory.mktemp("stand") / "ds")


def test_check_good_dataset(stand_ds, tmp_path):
    out = tmp_path / "check.json"
    res = cli("check", stand_ds, "--json", out)
    assert res.returncode == 0, res.stderr
    lines = res.stdout.splitlines()
    assert lines[0].split() == [
        "file", "ramp", "samples", "dur", "s", "rate", "Hz", "current", "mA", "p_clutch", "bar", "!"
    ]  # fmt: skip
    row = lines[2].split()
    assert row[:5] == ["medium_50Hz_B.csv", "medium", "23001", "23.000", "1000"]
    assert row[-1] == "0" and lines[-1] == f"{stand_ds}: OK"
    report = json.loads(out.read_text())
    assert report["ok"] is True and report["problems"] == []
    exp = report["experiments"][0]
    assert exp["ramp"] == "medium" and exp["samples"] == 23001 and exp["problems"] == []
    assert exp["rate_Hz"] == pytest.approx(1000.0) and exp["duration_s"] == pytest.approx(23.0)
    assert exp["ranges"]["clutch_pressure_bar"][1] > 15.0
    assert exp["timing"][0]["jitter_max_s"] < 1e-9


def test_check_bad_dataset_exits_non_zero_and_lists_every_problem(tmp_path):
    n = 100
    t = np.arange(n) * 1e-3
    good = Trace(
        "good",
        {"time_s": t, "current_mA": np.full(n, 300.0), "clutch_pressure_bar": t},
        meta={"ramp": "fast"},
    )
    root = save_dataset(Dataset([good]), tmp_path / "bad")
    lines = ["time_s,current_mA,clutch_pressure_bar"]
    lines += [f"{k * 1e-3:.3f},{0.3 if k != 7 else 'nan'},1.0" for k in range(n)]
    (root / "amps.csv").write_text("\n".join(lines) + "\n")
    manifest = json.loads((root / "manifest.json").read_text())
    manifest["experiments"] += [
        {"file": "amps.csv", "ramp": "slow"},
        {"file": "gone.csv", "ramp": "slow"},
    ]
    (root / "manifest.json").write_text(json.dumps(manifest))
    out = tmp_path / "bad.json"
    res = cli("check", root, "--json", out)
    assert res.returncode == 1
    text = res.stdout
    assert "good.csv" in text and "amps.csv" in text
    assert "3 problem(s)" in text
    assert f"experiments[2]: file 'gone.csv' not found ({root / 'gone.csv'})" in text
    assert (
        f"experiments[1]: {root / 'amps.csv'}: column 'current_mA': missing values (NaN/inf) "
        "at line 9 (data row 8) (1 × NaN)" in text
    )
    assert f"{root / 'amps.csv'}: column 'current_mA': implausible unit: values look like" in text
    report = json.loads(out.read_text())
    assert report["ok"] is False and len(report["experiments"]) == 2
    assert report["experiments"][0]["problems"] == []
    assert len(report["experiments"][1]["problems"]) == 2
    # with the right options the same file passes
    (tmp_path / "amps.toml").write_text(
        '[signals]\ncurrent_mA = { channel = "current_mA", unit = "A" }\n'
    )
    res = cli("check", root / "amps.csv", "--map", tmp_path / "amps.toml", "--interpolate-gaps", 1)
    assert res.returncode == 0, res.stdout
    assert "interpolated line 9 (data row 8)" in res.stdout


def test_convert_dataset_to_every_format(stand_ds, tmp_path):
    original = load_dataset(stand_ds)
    for fmt in ("parquet", "mf4"):
        res = cli("convert", stand_ds, tmp_path / fmt, "--format", fmt)
        assert res.returncode == 0, res.stderr
        back = load_dataset(tmp_path / fmt)
        assert back.names == original.names and back[0].meta == original[0].meta
        for name in original[0].signals:
            np.testing.assert_array_equal(back[0].get(name), original[0].get(name))
    res = cli("convert", stand_ds, tmp_path / "mf4", "--format", "mf4")
    assert res.returncode == 2 and "folder exists and is not empty" in res.stderr
    res = cli("convert", tmp_path / "mf4" / "medium_50Hz_B.mf4", tmp_path / "one.parquet")
    assert res.returncode == 0, res.stderr
    assert load_dataset(tmp_path / "parquet")[0].meta["ramp"] == "medium"


def test_failed_convert_leaves_no_partial_output(stand_ds, tmp_path, monkeypatch):
    # bad input: nothing written
    src = tmp_path / "src"
    save_dataset(load_dataset(stand_ds), src)
    (src / "medium_50Hz_B.csv").write_text("time_s,current_mA\n0,1\n")
    res = cli("convert", src, tmp_path / "dst", "--format", "mf4")
    assert res.returncode == 2
    assert res.stderr.startswith("clutchlab data convert: error: ")
    assert "required column 'clutch_pressure_bar' is missing" in res.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["src"]

    # a writer failing half-way: no folder, no file, no temporary left behind
    def failing(trace, path):
        path.write_bytes(b"partial")
        raise OSError("disk full")

    monkeypatch.setitem(FORMATS, ".mf4", FileFormat("mf4", FORMATS[".mf4"].decode, failing))
    with pytest.raises(OSError, match="disk full"):
        convert(stand_ds, tmp_path / "dst", format="mf4")
    with pytest.raises(OSError, match="disk full"):
        convert(stand_ds / "medium_50Hz_B.csv", tmp_path / "one.mf4")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["src"]
    with pytest.raises(DataError, match="suffix does not match the format 'csv'"):
        convert(stand_ds / "medium_50Hz_B.csv", tmp_path / "one.mf4", format="csv")


def test_check_into_a_closed_pipe_stops_quietly(stand_ds):
    """``clutchlab data check DS | head -1``: the reader goes away; no traceback."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "clutchlab.cli", "data", "check", str(stand_ds)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    proc.stdout.close()  # the reader is gone before the first line is written
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == 141
    assert "Traceback" not in err and "BrokenPipeError" not in err


@pytest.mark.parametrize("command", ["check", "convert"])
def test_a_path_that_does_not_exist_is_an_error_of_the_call(tmp_path, command):
    """``data check`` printed an empty table and exit 1 (a finding in the data); a path that
    is not there is an error of the call, exit 2, as ``data convert`` has it."""
    missing = tmp_path / "no_such_dataset"
    args = [str(missing)] + ([str(tmp_path / "out")] if command == "convert" else [])
    res = cli(command, *args)
    assert res.returncode == 2, res.stdout + res.stderr
    assert str(missing) in res.stderr and "file  ramp" not in res.stdout
    assert not (tmp_path / "out").exists()


def _undeclared_log(stand_ds, tmp_path, name: str):
    """A logger's export of one stand experiment: measured current and clutch pressure only,
    no dither frequency anywhere; its folder and manifest."""
    src = load_dataset(stand_ds)["medium_50Hz_B"]
    keep = ("time_s", "current_mA", "clutch_pressure_bar")
    own = Trace(name, {k: src.get(k) for k in keep}, meta={"ramp": "r10s"})
    root = save_dataset(Dataset([own]), tmp_path / "own")
    manifest = json.loads((root / "manifest.json").read_text())
    manifest["experiments"][0].pop("dither_freq_Hz", None)
    (root / "manifest.json").write_text(json.dumps(manifest))
    return root, manifest


def test_an_experiment_without_a_dither_frequency_gets_a_note(stand_ds, tmp_path, capsys):
    # A logger's export with the measured current only, no dither_freq_Hz column and none in
    # the manifest: dither_period_samples was then 1 sample, so the fit's cost, the ramp rate
    # and the report's "dither-period mean" scores averaged nothing, and nothing said so.
    from clutchlab.cli_types import print_dither_notes

    root, manifest = _undeclared_log(stand_ds, tmp_path, "r10s_run2")
    res = cli("check", root)
    assert res.returncode == 0, res.stderr
    (note,) = [ln for ln in res.stdout.splitlines() if "no dither frequency" in ln]
    assert f"{root / 'r10s_run2.csv'}: no dither frequency" in note
    assert "carries a dither at about 50 Hz" in note and '"dither_freq_Hz": 50' in note
    loaded = load_dataset(root)
    print_dither_notes(loaded)  # what fit-physics, evaluate and train print
    err = capsys.readouterr().err
    assert err.startswith(f"note: {root / 'r10s_run2.csv'}: no dither frequency"), err
    # the frequency found is the period of the means downstream (was 1 sample: DESIGN §3
    # says "demodulated if absent")
    assert loaded[0].meta["dither_freq_found_Hz"] == pytest.approx(50.0, rel=0.01)
    assert dither_period_samples(loaded[0]) == pytest.approx(20.0, rel=0.01)
    manifest["experiments"][0]["dither_freq_Hz"] = 50
    (root / "manifest.json").write_text(json.dumps(manifest))
    res = cli("check", root)
    assert res.returncode == 0 and "no dither frequency" not in res.stdout, res.stdout
    print_dither_notes(load_dataset(root))
    assert capsys.readouterr().err == ""


def test_convert_to_a_file_without_a_known_suffix_names_the_suffixes(stand_ds, tmp_path):
    # It said "pass format= one of csv, ...": a Python argument, and --format csv would
    # only have been refused next because the suffix does not match the format.
    log = stand_ds / "medium_50Hz_B.csv"
    for dst in (tmp_path / "out", tmp_path / "out.txt"):
        res = cli("convert", log, dst)
        assert res.returncode == 2 and not dst.exists(), res.stderr
        assert "name the file with one of the suffixes .csv, .parquet, .mf4, .mat" in res.stderr
        assert "format=" not in res.stderr
    res = cli("convert", log, tmp_path / "out.txt", "--format", "csv")
    assert res.returncode == 2 and "suffix does not match the format 'csv'" in res.stderr


def test_a_command_only_log_without_dither_amplitude_gets_a_note(stand_ds, tmp_path, capsys):
    # The command current only, no dither amplitude anywhere: the physics model ran with
    # 0 mA of dither and `train` failed later; data check said OK without a word.
    from clutchlab.cli_types import print_dither_notes

    src = load_dataset(stand_ds)["medium_50Hz_B"]
    keep = ("time_s", "current_cmd_mA", "dither_freq_Hz", "clutch_pressure_bar")
    own = Trace("r10s", {k: src.get(k) for k in keep}, meta={"ramp": "r10s"})
    root = save_dataset(Dataset([own]), tmp_path / "own")
    res = cli("check", root)
    assert res.returncode == 0, res.stderr
    (note,) = [ln for ln in res.stdout.splitlines() if "no dither amplitude" in ln]
    assert f"{root / 'r10s.csv'}: no dither amplitude (no 'dither_amp_mA' column" in note
    assert "the physics model is driven without dither" in note
    print_dither_notes(load_dataset(root))
    assert capsys.readouterr().err.startswith(f"note: {root / 'r10s.csv'}: no dither amplitude")
    manifest = json.loads((root / "manifest.json").read_text())
    manifest["experiments"][0]["dither_amp_mA"] = 100
    (root / "manifest.json").write_text(json.dumps(manifest))
    assert "no dither amplitude" not in cli("check", root).stdout


def test_the_fitting_commands_print_three_dither_notes_in_full_and_name_the_rest(capsys):
    # 27 logs without a dither frequency printed 27 notes of ~400 characters before a fit.
    from pathlib import Path
    from types import SimpleNamespace

    from clutchlab.cli_types import MAX_NOTES_SHOWN, print_dither_notes
    from clutchlab.data.demodulate import no_dither_frequency_note
    from clutchlab.data.report import LoadReport

    reports = {
        f"r{k}": LoadReport(Path(f"logs/r{k}.csv"), "csv", f"r{k}", notes=(
            no_dither_frequency_note(50.0),
        ))
        for k in range(MAX_NOTES_SHOWN + 2)
    }  # fmt: skip
    print_dither_notes(SimpleNamespace(reports=reports))
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == MAX_NOTES_SHOWN + 1, lines
    assert lines[0].startswith("note: logs/r0.csv: no dither frequency")
    assert lines[-1] == (
        f"note: no dither frequency either in 2 more experiment(s): r{MAX_NOTES_SHOWN}.csv, "
        f"r{MAX_NOTES_SHOWN + 1}.csv (`clutchlab data check` lists each)"
    )


@pytest.mark.parametrize(
    "command",
    [
        ["fit-physics", "--out", "{tmp}/fit.json", "--train", "nope"],
        ["evaluate", "--out", "{tmp}/rep", "--train", "nope"],
        ["train", "--variant", "gp_base", "--out", "{tmp}/m", "--train", "nope"],
        ["classifiers", "--out", "{tmp}/c", "--train", "nope"],
        ["discover", "--out", "{tmp}/d", "--train", "nope"],
        ["select-structure", "--out", "{tmp}/s.json", "--train", "nope"],
    ],
)
def test_every_fitting_command_prints_the_dither_note_first(stand_ds, tmp_path, capsys, command):
    # `train` (and discover, select-structure) loaded the data without a word about a log
    # whose dither the analyses cannot average out.
    from clutchlab.cli import main

    root, _ = _undeclared_log(stand_ds, tmp_path, "r10s")
    args = [command[0], str(root), *(a.format(tmp=tmp_path) for a in command[1:])]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"note: {root / 'r10s.csv'}: no dither frequency"), err
    assert "nope" in err
