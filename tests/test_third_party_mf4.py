"""A calibration tool's multi-rate MF4 (``../shared/third_party/ASAP2_Demo_V171.mf4``, issue
18 must-show 3): read in place through a channel map, every problem named with channel,
group and row, no traceback — through the API and the CLI."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from clutchlab.data import check_log

MF4 = Path(__file__).resolve().parents[1].parent / "shared" / "third_party" / "ASAP2_Demo_V171.mf4"
MAP = """
[signals]
current_mA = { channel = "ASAM.M.SCALAR.FLOAT64.IDENTICAL", unit = "mA" }   # FLOAT64, 10 ms
clutch_pressure_bar = { channel = "ASAM.M.VIRTUAL.SCALAR.SWORD.PHYSICAL", unit = "bar" }  # SWORD

[defaults]
dither_freq_Hz = 50.0
"""


@pytest.fixture(scope="module")
def mf4() -> Path:
    assert MF4.is_file(), (
        f"{MF4} is missing: the third-party conformance files must sit in ../shared/third_party "
        "beside the project (see its README)"
    )
    return MF4


def test_checked_through_a_channel_map_with_every_problem_named(mf4, tmp_path):
    cmap = tmp_path / "asap2.toml"
    cmap.write_text(MAP)
    trace, report = check_log(mf4, channel_map=cmap)
    assert trace is None  # not clutch data: the plausibility checks speak
    assert report.problems
    for problem in report.problems:
        assert str(mf4) in problem and "channel 'ASAM." in problem and "(group " in problem
    assert any("row" in p for p in report.problems)
    assert any("not in the channel map ignored" in n for n in report.notes)
    assert any("unit 'hours' in the file ignored" in n for n in report.notes)


def test_cli_check_lists_the_problems_without_a_traceback(mf4, tmp_path):
    cmap = tmp_path / "asap2.toml"
    cmap.write_text(MAP)
    res = subprocess.run(
        [sys.executable, "-m", "clutchlab.cli", "data", "check", str(mf4), "--map", str(cmap)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert res.returncode == 1, res.stderr
    assert "Traceback" not in res.stderr + res.stdout
    assert "ASAM.M.VIRTUAL.SCALAR.SWORD.PHYSICAL" in res.stdout
