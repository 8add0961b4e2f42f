"""Parquet and MF4 readers/writers, round trips, multi-rate and irregular logs."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from asammdf import MDF, Signal

from clutchlab.data import (
    CANONICAL_ORDER,
    SIGNALS,
    Dataset,
    ReadOptions,
    Trace,
    load_dataset,
    read_csv,
    read_log,
    read_mf4,
    read_parquet,
    save_dataset,
    write_csv,
    write_mf4,
    write_parquet,
)
from clutchlab.errors import DataError
from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, run_stand

FLOAT32_EPS = float(np.finfo(np.float32).eps)


@pytest.fixture(scope="module")
def stand_dataset() -> Dataset:
    """Two realistic stand experiments (every canonical signal) with rich metadata."""
    run = run_stand(
        StandConfig(
            settings=(DitherSetting(50.0, "B"), DitherSetting(30.0, "A", "triangle")),
            ramps=(RampProfile("fast", 2.5),),
        ),
        progress=False,
    )
    traces = [
        Trace(t.name, t.signals, meta={**t.meta, "operator": "ü-test", "tags": [1, "a", None]})
        for t in run.dataset
    ]
    extra = {**run.dataset.manifest_extra, "stand": {"id": 7, "limits": [0.5, 17.7]}}
    return Dataset(traces, manifest_extra=extra)


def _manifest(root):
    return json.loads((root / "manifest.json").read_text(encoding="utf-8"))


def test_round_trip_csv_parquet_mf4_csv_within_float32(tmp_path, stand_dataset):
    # Must-show 1: CSV → Parquet → MF4 → CSV, every signal equal within float32 precision,
    # manifest metadata preserved.
    roots = []
    ds = stand_dataset
    for fmt in ("csv", "parquet", "mf4", "csv"):
        roots.append(save_dataset(ds, tmp_path / f"{len(roots)}_{fmt}", fmt))
        ds = load_dataset(roots[-1])
    first, last = roots[0], roots[-1]
    suffixes = [
        sorted(p.suffix for p in root.iterdir() if p.name != ".clutchlab-owned.json")
        for root in roots
    ]
    assert suffixes[1] == [".json", ".parquet", ".parquet"]
    assert suffixes[2] == [".json", ".mf4", ".mf4"]
    assert _manifest(last) == _manifest(first)  # same files, ramps, every free key
    assert ds.manifest_extra == stand_dataset.manifest_extra
    for a, b in zip(stand_dataset, ds, strict=True):
        assert b.name == a.name and b.meta == a.meta
        assert list(b.signals) == list(a.signals) == list(CANONICAL_ORDER)
        for name in a.signals:
            np.testing.assert_allclose(b.get(name), a.get(name), rtol=FLOAT32_EPS, atol=0)


def test_parquet_and_mf4_are_exact_and_carry_units_and_meta(tmp_path, stand_dataset):
    trace = stand_dataset[0]
    pq_path = write_parquet(trace, tmp_path / "x.parquet")
    mf_path = write_mf4(trace, tmp_path / "x.mf4")
    for back in (read_parquet(pq_path), read_mf4(mf_path)):
        assert back.name == trace.name  # embedded, not the file stem
        assert back.meta == trace.meta
        for name in trace.signals:
            np.testing.assert_array_equal(back.get(name), trace.get(name), err_msg=name)

    import pyarrow.parquet as pq

    schema = pq.read_schema(pq_path)
    assert {f.name: f.metadata[b"unit"].decode() for f in schema} == trace.units
    mdf = MDF(mf_path)
    try:
        units = {ch.name: ch.unit for g in mdf.groups for ch in g.channels}
    finally:
        mdf.close()
    assert units["time"] == "s"
    for name in trace.signals:
        if name != "time_s":
            assert units[name] == SIGNALS[name].unit, name


def _write_time_typed_parquet(path, arrow_type, n=3000):
    """A 1 kHz log whose time column is an Arrow timestamp / duration (epoch nanoseconds)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    ticks = 1_700_000_000_000_000_000 + np.arange(n, dtype=np.int64) * 1_000_000  # 1 ms
    table = pa.table(
        {
            "time_s": pa.array(ticks, pa.int64()).cast(arrow_type),
            "current_mA": np.full(n, 400.0),
            "clutch_pressure_bar": np.linspace(0.5, 10.0, n),
        }
    )
    pq.write_table(table, path)
    return path


@pytest.mark.parametrize("arrow_type", ["timestamp[ns]", "duration[ns]"])
def test_parquet_time_typed_column_keeps_exact_steps(tmp_path, arrow_type):
    # epoch nanoseconds (1.7e18) are beyond float64's 2**53: the first sample is subtracted
    # in int64 ticks, before the conversion, so 1 ms steps stay 1 ms (not 999936 / 1000192 ns)
    import pyarrow as pa

    arrow = pa.timestamp("ns") if arrow_type.startswith("timestamp") else pa.duration("ns")
    path = _write_time_typed_parquet(tmp_path / "ts.parquet", arrow)
    trace, report = read_log(path)
    np.testing.assert_allclose(np.diff(trace.time_s), 1e-3, rtol=0, atol=1e-12)
    assert trace.time_s[0] == 0.0
    assert report.rate_Hz == pytest.approx(1000.0, rel=1e-9)


@pytest.mark.parametrize("arrow_type", ["timestamp[ns]", "duration[ns]"])
def test_parquet_time_typed_column_refuses_a_map_unit(tmp_path, arrow_type):
    # the decoder already turned the column into seconds: a map unit 'ms' would convert it a
    # second time (a 1 kHz, 3 s log read as 1 MHz, 3 ms)
    import pyarrow as pa

    arrow = pa.timestamp("ns") if arrow_type.startswith("timestamp") else pa.duration("ns")
    path = _write_time_typed_parquet(tmp_path / "ts.parquet", arrow)
    cmap = {"signals": {"time_s": {"channel": "time_s", "unit": "ms"}}}
    with pytest.raises(DataError) as info:
        read_log(path, channel_map=cmap)
    assert (
        f"{path}: column 'time_s': is {arrow_type}, already in seconds; the map's unit 'ms' "
        "does not apply" in str(info.value)
    )
    # the unit it already has is fine
    trace = read_log(path, channel_map={"signals": {"time_s": {"channel": "time_s", "unit": "s"}}})
    assert trace[0].time_s[-1] == pytest.approx(2.999, abs=1e-12)


def _identity(x):
    return x


def _write_multirate(path, names=None, units=None, to_units=(_identity,) * 3):
    """Three groups: 1 kHz from 0 s, 500 Hz from 0.010 s, 10 Hz from 0.050 s, to ~2 s.

    Current 100 + 200 t mA, pressure 1 + 2 t bar, temperature 40 + 10 sin(t) °C, each
    converted to the logged unit by ``to_units``.
    """
    names = names or ("current_mA", "clutch_pressure_bar", "oil_temp_C")
    units = units or ("mA", "bar", "°C")
    t1 = np.arange(0, 2000) * 1e-3
    t2 = 0.010 + np.arange(0, 995) * 2e-3
    t3 = 0.050 + np.arange(0, 20) * 0.1
    values = (100.0 + 200.0 * t1, 1.0 + 2.0 * t2, 40.0 + 10.0 * np.sin(t3))
    mdf = MDF(version="4.10")
    for t, v, name, unit, conv in zip((t1, t2, t3), values, names, units, to_units, strict=True):
        mdf.append([Signal(conv(v), t, name=name, unit=unit)])
    mdf.save(path, overwrite=True)
    mdf.close()
    return t1, t2, t3


def test_multirate_mf4_three_rates_on_one_grid(tmp_path):
    # Must-show 4: current 1 kHz, pressure 500 Hz, temperature 10 Hz → one 1 kHz grid.
    path = tmp_path / "multi.mf4"
    t1, t2, t3 = _write_multirate(path)
    trace, report = read_log(path)
    t = trace.time_s
    np.testing.assert_allclose(np.diff(t), 1e-3, rtol=1e-9)
    assert t[0] == pytest.approx(0.050) and t[-1] == pytest.approx(min(t1[-1], t2[-1], t3[-1]))
    assert sorted(round(tm.rate_Hz, 6) for tm in report.timing) == [10.0, 500.0, 1000.0]
    assert "3 time bases" in report.resampled
    assert any("[0.05, 1.95] s, the span every channel covers" in n for n in report.notes)

    def at(name, when):
        return float(np.interp(when, t, trace.get(name)))

    for when in (0.050, 0.5, 1.0, 1.2345, 1.75, 1.950):
        i = int(np.argmin(np.abs(t - when)))
        assert t[i] == pytest.approx(when, abs=1e-9) or when == 1.2345
        # linear channels are reproduced exactly at any instant
        assert at("current_mA", when) == pytest.approx(100.0 + 200.0 * when, abs=1e-9)
        assert at("clutch_pressure_bar", when) == pytest.approx(1.0 + 2.0 * when, abs=1e-9)
    for k in (0, 4, 10, 19):  # the 10 Hz samples fall on the grid: exact there
        when = 0.050 + 0.1 * k
        i = int(np.argmin(np.abs(t - when)))
        assert trace.get("oil_temp_C")[i] == pytest.approx(40.0 + 10.0 * np.sin(when), abs=1e-9)
    mid = 0.050 + 0.1 * 7.5  # between two 10 Hz samples: linear interpolation
    expected = 40.0 + 5.0 * (np.sin(0.050 + 0.7) + np.sin(0.050 + 0.8))
    assert at("oil_temp_C", mid) == pytest.approx(expected, abs=1e-9)


def test_multirate_mf4_with_channel_map_and_units(tmp_path):
    path = tmp_path / "logger.mf4"
    _write_multirate(
        path,
        names=("I_VFS", "P_CL", "T_oil"),
        units=("A", "kPa", "degF"),
        to_units=(lambda i: i / 1000.0, lambda p: p * 100.0, lambda c: c * 1.8 + 32.0),
    )
    cmap = {
        "signals": {
            "current_mA": "I_VFS",  # unit taken from the file (A)
            "clutch_pressure_bar": {"channel": "P_CL"},
            "oil_temp_C": {"channel": "T_oil", "unit": "°F"},
        },
        "defaults": {"line_pressure_bar": 18.0},
    }
    trace, report = read_log(path, channel_map=cmap)
    t = trace.time_s
    i = int(np.argmin(np.abs(t - 1.0)))
    assert trace.get("current_mA")[i] == pytest.approx(300.0, rel=1e-12)
    assert trace.get("clutch_pressure_bar")[i] == pytest.approx(3.0, rel=1e-12)
    k = int(np.argmin(np.abs(t - 1.050)))  # a 10 Hz sample instant
    assert trace.get("oil_temp_C")[k] == pytest.approx(40.0 + 10.0 * np.sin(1.050), rel=1e-12)
    assert trace.get("line_pressure_bar")[i] == 18.0
    assert report.defaults == {"line_pressure_bar": 18.0}
    assert "[A → mA]" in report.sources["current_mA"]
    assert "[kPa → bar]" in report.sources["clutch_pressure_bar"]
    assert "[°F → °C]" in report.sources["oil_temp_C"]


def test_irregular_csv_is_resampled_and_jitter_reported(tmp_path):
    rng = np.random.default_rng(3)
    n = 3000
    t = 5.0 + np.arange(n) * 1e-3 + rng.uniform(-0.2e-3, 0.2e-3, n)  # ±20 % jitter
    trace = Trace(
        "jit",
        {"time_s": t, "current_mA": 200.0 + 100.0 * t, "clutch_pressure_bar": 2.0 + 0.5 * t},
    )
    path = write_csv(trace, tmp_path / "jit.csv")
    back, report = read_log(path)
    jitter = report.timing[0]
    assert 0.15e-3 < jitter.jitter_max_s < 0.25e-3
    assert "jitter up to" in report.resampled
    grid = back.time_s
    np.testing.assert_allclose(np.diff(grid), np.diff(grid).mean(), rtol=1e-9)
    assert grid[0] >= t[0] and grid[-1] <= t[-1]
    np.testing.assert_allclose(back.get("current_mA"), 200.0 + 100.0 * grid, rtol=1e-8)
    # within the tolerance (default 1 % of the interval) the time stamps are kept as logged
    regular = 5.0 + np.arange(n) * 1e-3 + rng.uniform(-5e-6, 5e-6, n)  # ±0.5 %
    small = Trace("ok", {**trace.signals, "time_s": regular})
    kept, report = read_log(write_csv(small, tmp_path / "ok.csv"))
    assert report.resampled is None and report.timing[0].jitter_max_s < 6e-6
    np.testing.assert_allclose(kept.time_s, small.time_s, rtol=5e-9, atol=0)
    resampled = read_csv(tmp_path / "ok.csv", options=ReadOptions(rate_Hz=500.0))
    assert resampled.sample_rate_Hz == pytest.approx(500.0)


def test_time_gaps_are_errors_unless_interpolated(tmp_path):
    t = np.delete(np.arange(1000) * 1e-3, [300, 301, 302])  # 3 samples dropped
    trace = Trace("gap", {"time_s": t, "current_mA": 500.0 + t, "clutch_pressure_bar": 1.0 + t})
    path = write_parquet(trace, tmp_path / "gap.parquet")
    with pytest.raises(Exception) as info:
        read_parquet(path)
    text = str(info.value)
    assert "gap.parquet: column 'time_s': time gap(s) of missing samples before row 301" in text
    assert "(3 missing)" in text and "interpolate_gaps=3" in text
    back, report = read_log(path, options=ReadOptions(interpolate_gaps=3))
    assert len(back) == 1000
    assert any("interpolated time gap" in f for f in report.filled)
    np.testing.assert_allclose(back.get("current_mA"), 500.0 + back.time_s, rtol=1e-12)


def test_save_dataset_in_every_format_and_reports(tmp_path, stand_dataset):
    for fmt, suffix in (("csv", ".csv"), ("parquet", ".parquet"), ("mf4", ".mf4")):
        root = save_dataset(stand_dataset, tmp_path / fmt, format=fmt)
        manifest = _manifest(root)
        assert [e["file"] for e in manifest["experiments"]] == [
            t.name + suffix for t in stand_dataset
        ]
        back = load_dataset(root)
        assert set(back.reports) == set(back.names)
        report = back.reports[back.names[0]]
        assert report.format == fmt and report.rate_Hz == pytest.approx(1000.0)
        assert report.ok and report.resampled is None


def test_data_layer_does_not_import_physics():
    code = (
        "import sys, clutchlab.data, clutchlab.data.demodulate, clutchlab.data.check, "
        "clutchlab.data.convert\n"
        "bad = [m for m in sys.modules if m.startswith(('clutchlab.physics', "
        "'clutchlab.residual_ml', 'clutchlab.validation'))]\n"
        "assert not bad, bad\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_parquet_pandas_index_column_is_ignored(tmp_path):
    """pandas writes an unnamed, non-range index as ``__index_level_0__``: not a channel."""
    import pandas as pd

    from clutchlab.data import read_log

    n = 400
    df = pd.DataFrame(
        {
            "time_s": np.arange(n) * 1e-3,
            "current_mA": np.linspace(0.0, 500.0, n),
            "clutch_pressure_bar": np.linspace(0.5, 5.0, n),
        },
        index=np.arange(n) * 2,  # not a RangeIndex from 0: stored as a column
    )
    path = tmp_path / "idx.parquet"
    df.to_parquet(path)
    trace, report = read_log(path)
    np.testing.assert_array_equal(trace.get("current_mA"), df["current_mA"].to_numpy())
    assert any("'__index_level_0__' ignored" in n for n in report.notes)


def test_slow_mf4_group_and_offset_clock_get_no_time_unit_note(tmp_path):
    # A logger's 1 Hz temperature group (as in a calibration tool's MF4) and a clock that
    # starts at 1234.5 s: the master channels are in seconds, nothing to ask. The note used
    # to say "time of group 1 (master channel): sample rate 1 Hz: is the time in seconds? A
    # time logged in ms ... needs its unit in the channel map", which an MF4 master cannot
    # take, and "sample rate 10 Hz" for a 10 Hz group (9.9999… from the offset clock).
    t1 = 1234.5 + np.arange(0, 3000) * 1e-3
    mdf = MDF(version="4.10")
    mdf.append([Signal(100.0 + 100.0 * (t1 - t1[0]), t1, name="current_mA", unit="mA")])
    mdf.append([Signal(2.0 + 0 * t1[::100], t1[::100], name="clutch_pressure_bar", unit="bar")])
    mdf.append([Signal(40.0 + 0 * t1[::1000], t1[::1000], name="oil_temp_C", unit="°C")])
    mdf.save(tmp_path / "slow.mf4", overwrite=True)
    mdf.close()
    _, report = read_log(tmp_path / "slow.mf4")
    assert sorted(round(tm.rate_Hz, 3) for tm in report.timing) == [1.0, 10.0, 1000.0]
    assert not [n for n in report.notes if "is the time in seconds" in n], report.notes
