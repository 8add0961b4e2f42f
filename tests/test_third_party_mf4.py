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


def test_source_qualified_channel_map(mf4, tmp_path):
    """Issue 19 must-show 3: a channel named with the source it was logged from."""
    cmap = {
        "signals": {
            "current_mA": {
                "channel": "ASAM.M.SCALAR.FLOAT64.IDENTICAL",
                "unit": "mA",
                "source": "ETK test device:1",  # the device, as the tool wrote it
            },
            "clutch_pressure_bar": {
                "channel": "ASAM.M.VIRTUAL.SCALAR.SWORD.PHYSICAL",
                "unit": "bar",
                "source": "Leading_All",
            },
        },
        "defaults": {"dither_freq_Hz": 50.0},
    }
    _, report = check_log(mf4, channel_map=cmap)
    assert not [p for p in report.problems if "source" in p]
    assert any("implausible unit" in p for p in report.problems)  # the same data was read
    cmap["signals"]["current_mA"]["source"] = "Engine_1"
    _, report = check_log(mf4, channel_map=cmap)
    assert any(
        "is not logged from source 'Engine_1'; its sources: 'ETK test device:1', 'Engine_3'" in p
        for p in report.problems
    )


def test_a_name_under_several_sources_is_refused_with_the_sources_listed(tmp_path):
    import numpy as np
    from asammdf import MDF, Signal
    from asammdf.blocks.source_utils import Source

    t = np.arange(0.0, 2.0, 0.001)
    mdf = MDF(version="4.10")
    for name, level, acq in (("ECU_A", 5.0, "Stand_A"), ("LOGGER_B", 6.0, "Stand_B")):
        src = Source(name, "CAN1", "", Source.SOURCE_ECU, Source.BUS_TYPE_CAN)
        current = 500.0 + 100.0 * np.sin(2 * np.pi * 50.0 * t)
        mdf.append(
            [
                Signal(np.full(t.size, level), t, name="P_CL", unit="bar", source=src),
                Signal(current, t, name="I_sol", unit="mA", source=src),
            ],
            acq_name=acq,
            acq_source=src,
        )
    path = tmp_path / "two_sources.mf4"
    mdf.save(path, overwrite=True)
    cmap = {
        "signals": {"clutch_pressure_bar": "P_CL", "current_mA": {"channel": "I_sol"}},
        "defaults": {"dither_freq_Hz": 50.0},
    }
    _, report = check_log(path, channel_map=cmap)
    text = "\n".join(report.problems)
    assert "'P_CL' (clutch_pressure_bar) is ambiguous" in text
    assert "'Stand_A', 'ECU_A'" in text and "'Stand_B', 'LOGGER_B'" in text
    for signal in ("clutch_pressure_bar", "current_mA"):
        name = cmap["signals"][signal]
        cmap["signals"][signal] = {"channel": name if isinstance(name, str) else "I_sol"}
        cmap["signals"][signal]["source"] = "LOGGER_B"
    trace, report = check_log(path, channel_map=cmap)
    assert trace is not None, report.problems
    assert np.allclose(trace.get("clutch_pressure_bar"), 6.0)


def test_a_wrong_group_names_the_group_the_channel_is_in(mf4, tmp_path):
    cmap = tmp_path / "group.toml"
    cmap.write_text(
        MAP.replace('unit = "mA" }', 'unit = "mA", group = 7 }').replace(
            'channel = "ASAM.M.VIRTUAL.SCALAR.SWORD.PHYSICAL"',
            'channel = "ASAM.M.VIRTUAL.SCALAR.SWORD.PHYSICAL", source = "no such device"',
        )
    )
    _, report = check_log(mf4, channel_map=cmap)
    text = "\n".join(report.problems)
    assert "is not in group 7; it is in group" in text
    assert "not logged from source 'no such device'" in text
    assert "required column" not in text and "is required" not in text  # each said once


def test_a_refused_multi_rate_log_is_described_at_one_rate(mf4, tmp_path):
    # The row of `data check` for the refused log read "1240 samples, 12.390 s, 1000 Hz":
    # the samples of the 10 ms group beside the rate of the 1 ms group.
    cmap = tmp_path / "asap2.toml"
    cmap.write_text(
        MAP.replace(
            "[defaults]",
            'oil_temp_C = { channel = "ASAM.M.SCALAR.UBYTE.FORM_X_PLUS_4", unit = "degC" }'
            "  # 10 ms\n\n[defaults]",
        )
    )
    trace, report = check_log(mf4, channel_map=cmap)
    assert trace is None and report.problems
    assert report.rate_Hz == pytest.approx(1000.0, rel=1e-3)
    assert report.samples == pytest.approx(report.duration_s * report.rate_Hz + 1, rel=0.01)
