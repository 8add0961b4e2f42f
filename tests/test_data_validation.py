"""One test per bad-input case: the DataError names the file, the column and the row."""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from asammdf import MDF, Signal

from clutchlab.data import (
    Dataset,
    ReadOptions,
    Trace,
    load_dataset,
    read_csv,
    read_log,
    read_mf4,
    read_parquet,
    save_dataset,
    validate_trace,
    write_csv,
    write_mf4,
    write_parquet,
)
from clutchlab.errors import DataError

N = 200


def signals(n: int = N, rate: float = 1000.0, **over) -> dict[str, np.ndarray]:
    t = np.arange(n) / rate
    base = {
        "time_s": t,
        "current_mA": 400.0 + 100.0 * np.sin(2 * np.pi * 50.0 * t),
        "dither_freq_Hz": np.full(n, 50.0),
        "clutch_pressure_bar": 2.0 + t,
        "oil_temp_C": np.full(n, 60.0),
    }
    base.update(over)
    return base


def write_raw_csv(path, sig: dict[str, np.ndarray]):
    """CSV without going through Trace (which would refuse some of the bad inputs)."""
    names = list(sig)
    rows = zip(*(sig[k] for k in names), strict=True)
    path.write_text(
        ",".join(names) + "\n" + "".join(",".join(repr(float(v)) for v in r) + "\n" for r in rows),
        encoding="utf-8",
    )
    return path


def write_raw_parquet(path, sig):
    pq.write_table(pa.table({k: pa.array(v) for k, v in sig.items()}), path)
    return path


def write_raw_mf4(path, sig, groups=None):
    """MF4 with every channel in one group (or per ``groups``: list of name lists)."""
    t = sig["time_s"]
    mdf = MDF(version="4.10")
    for names in groups or [[k for k in sig if k != "time_s"]]:
        mdf.append([Signal(sig[k], t, name=k) for k in names])
    mdf.save(path, overwrite=True)
    mdf.close()
    return path


def problems_of(call) -> str:
    with pytest.raises(DataError) as info:
        call()
    return str(info.value)


# -- missing required column ---------------------------------------------------------------


@pytest.mark.parametrize("fmt", ["csv", "parquet", "mf4"])
def test_missing_required_column(tmp_path, fmt):
    sig = signals()
    del sig["clutch_pressure_bar"]
    writer = {"csv": write_raw_csv, "parquet": write_raw_parquet, "mf4": write_raw_mf4}[fmt]
    path = writer(tmp_path / f"log.{fmt}", sig)
    text = problems_of(lambda: read_log(path))
    assert f"{path}: required column 'clutch_pressure_bar' is missing" in text
    sig = signals()
    del sig["current_mA"]
    path = writer(tmp_path / f"nocurrent.{fmt}", sig)
    assert "one of the columns 'current_mA' / 'current_cmd_mA' is required" in problems_of(
        lambda: read_log(path)
    )


# -- NaN / inf runs ------------------------------------------------------------------------


def test_nan_run_in_csv_names_column_and_lines(tmp_path):
    p = signals()["clutch_pressure_bar"].copy()
    p[50:53] = np.nan
    p[120] = np.inf
    path = write_raw_csv(tmp_path / "nan.csv", signals(clutch_pressure_bar=p))
    text = problems_of(lambda: read_csv(path))
    assert (
        f"{path}: column 'clutch_pressure_bar': missing values (NaN/inf) at "
        "line 52 (data row 51) to line 54 (data row 53) (3 × NaN); line 122 (data row 121) "
        "(1 × +inf) (pass interpolate_gaps=3 to fill runs up to 3 samples: "
        "ReadOptions(interpolate_gaps=3), or `clutchlab data convert --interpolate-gaps 3` "
        "for a filled copy to fit on)"
    ) in text
    # explicit option: filled by interpolation and reported
    trace, report = read_log(path, options=ReadOptions(interpolate_gaps=3))
    np.testing.assert_allclose(trace.get("clutch_pressure_bar"), signals()["clutch_pressure_bar"])
    assert report.filled == (
        f"{path}: column 'clutch_pressure_bar': interpolated line 52 (data row 51) to line 54 "
        "(data row 53) (3 × NaN); line 122 (data row 121) (1 × +inf)",
    )
    # a longer run than allowed is still an error
    text = problems_of(lambda: read_csv(path, options=ReadOptions(interpolate_gaps=2)))
    assert "(longer than interpolate_gaps = 2)" in text


def test_nan_run_in_parquet_and_mf4_names_rows(tmp_path):
    i = signals()["current_mA"].copy()
    i[10:12] = np.nan
    pq_path = write_raw_parquet(tmp_path / "nan.parquet", signals(current_mA=i))
    assert (
        f"{pq_path}: column 'current_mA': missing values (NaN/inf) at row 11 to row 12 (2 × NaN)"
        in problems_of(lambda: read_parquet(pq_path))
    )
    sig = signals(current_mA=i)
    mf_path = write_raw_mf4(
        tmp_path / "nan.mf4",
        sig,
        groups=[["clutch_pressure_bar", "dither_freq_Hz", "oil_temp_C"], ["current_mA"]],
    )
    assert (
        f"{mf_path}: channel 'current_mA' (group 1): missing values (NaN/inf) at row 11 to row "
        "12 (2 × NaN)" in problems_of(lambda: read_mf4(mf_path))
    )
    # edges are filled with the nearest value
    i = signals()["current_mA"].copy()
    i[:2] = np.nan
    path = write_raw_parquet(tmp_path / "edge.parquet", signals(current_mA=i))
    trace = read_parquet(path, options=ReadOptions(interpolate_gaps=2))
    assert trace.get("current_mA")[0] == trace.get("current_mA")[2]


# -- time ----------------------------------------------------------------------------------


def test_non_monotonic_and_duplicate_time(tmp_path):
    t = signals()["time_s"].copy()
    t[[40, 41]] = t[[41, 40]]  # swapped: goes back at row 42
    t[100] = t[99]  # duplicate at row 101
    path = write_raw_csv(tmp_path / "time.csv", signals(time_s=t))
    text = problems_of(lambda: read_csv(path))
    assert (
        f"{path}: column 'time_s': not strictly increasing at line 43 (data row 42) "
        "(first: 0.04 s after 0.041 s)" in text
    )
    assert (
        f"{path}: column 'time_s': duplicate time stamp at line 102 (data row 101) "
        "(first: 0.099 s, same as line 101 (data row 100))" in text
    )
    sig = signals(time_s=t)
    mf_path = write_raw_mf4(tmp_path / "time.mf4", sig)
    text = problems_of(lambda: read_mf4(mf_path))
    assert f"{mf_path}: time of group 0 (master channel): not strictly increasing at row 42" in text


# -- implausible units and physical range ----------------------------------------------------


def test_current_in_amperes(tmp_path):
    path = write_raw_csv(
        tmp_path / "amps.csv", signals(current_mA=signals()["current_mA"] / 1000.0)
    )
    text = problems_of(lambda: read_csv(path))
    assert f"{path}: column 'current_mA': implausible unit: values look like amperes" in text
    assert "the unit must be mA (at line" in text


def test_pressure_in_kpa_and_psi(tmp_path):
    p = signals()["clutch_pressure_bar"] * 100.0  # kPa
    path = write_raw_parquet(tmp_path / "kpa.parquet", signals(clutch_pressure_bar=p))
    text = problems_of(lambda: read_parquet(path))
    assert (
        f"{path}: column 'clutch_pressure_bar': implausible unit: values look like kPa or psi "
        f"(largest {p.max():g}); the unit must be bar (gauge) (at row {N})" in text
    )


def test_temperature_in_fahrenheit_and_kelvin(tmp_path):
    warm_up = np.linspace(40.0, 120.0, N)  # °C
    path = write_raw_csv(tmp_path / "f.csv", signals(oil_temp_C=warm_up * 1.8 + 32))
    assert (
        f"{path}: column 'oil_temp_C': implausible unit: values look like °F (104 to 248); "
        f"the unit must be °C (at line {N + 1} (data row {N}))"
        in problems_of(lambda: read_csv(path))
    )
    path = write_raw_csv(tmp_path / "k.csv", signals(oil_temp_C=warm_up + 273.15))
    assert "column 'oil_temp_C': implausible unit: values look like kelvin or °F" in problems_of(
        lambda: read_csv(path)
    )


def test_values_out_of_physical_range(tmp_path):
    p = signals()["clutch_pressure_bar"].copy()
    p[77] = -3.0  # below vacuum (gauge)
    i = signals()["current_mA"].copy()
    i[150] = 5000.0  # one spike
    path = write_raw_mf4(tmp_path / "range.mf4", signals(clutch_pressure_bar=p, current_mA=i))
    text = problems_of(lambda: read_mf4(path))
    assert (
        f"{path}: channel 'clutch_pressure_bar' (group 0): value(s) outside the physical range "
        "[-1, 60] bar at row 78 = -3" in text
    )
    assert (
        f"{path}: channel 'current_mA' (group 0): value(s) outside the physical range "
        "[-300, 2000] mA at row 151 = 5000" in text
    )


# -- empty and truncated files ---------------------------------------------------------------


def test_empty_files(tmp_path):
    for name in ("e.csv", "e.parquet", "e.mf4"):
        (tmp_path / name).write_bytes(b"")
        assert f"{tmp_path / name}: empty file" in problems_of(
            lambda n=name: read_log(tmp_path / n)
        )
    (tmp_path / "h.csv").write_text("time_s,current_mA,clutch_pressure_bar\n")
    assert "h.csv: empty file (header but no data rows)" in problems_of(
        lambda: read_csv(tmp_path / "h.csv")
    )
    sig = {k: v[:0] for k, v in signals().items()}
    path = write_raw_parquet(tmp_path / "rows.parquet", sig)
    assert f"{path}: empty file (no rows)" in problems_of(lambda: read_parquet(path))
    mdf = MDF(version="4.10")
    mdf.save(tmp_path / "nochan.mf4", overwrite=True)
    mdf.close()
    assert "nochan.mf4: no data channels (empty measurement)" in problems_of(
        lambda: read_mf4(tmp_path / "nochan.mf4")
    )


def test_truncated_files(tmp_path):
    trace = Trace("t", signals())
    path = write_csv(trace, tmp_path / "t.csv")
    text = path.read_text()
    path.write_text(text[: text.rindex(",")])  # the last line loses its last field
    assert f"{path}: file truncated: line {N + 1} (data row {N}) has 4 of 5 fields" in (
        problems_of(lambda: read_csv(path))
    )
    expected = {
        ".parquet": "not a readable Parquet file (truncated or corrupt?)",
        ".mf4": "damaged MDF file (refused before parsing): ",
    }
    for writer, suffix in ((write_parquet, ".parquet"), (write_mf4, ".mf4")):
        full = writer(trace, tmp_path / f"full{suffix}")
        cut = tmp_path / f"cut{suffix}"
        cut.write_bytes(full.read_bytes()[: full.stat().st_size * 2 // 3])
        assert f"{cut}: {expected[suffix]}" in problems_of(lambda c=cut: read_log(c))


def test_truncated_mf4_names_the_file_once_and_says_truncated(tmp_path):
    # A DataError from the structure walk is a ValueError too: it was caught and wrapped
    # again, so the message said "FILE: damaged MDF file (...): FILE: damaged MDF file ...".
    full = write_mf4(Trace("t", signals()), tmp_path / "full.mf4")
    cut = tmp_path / "cut.mf4"
    cut.write_bytes(full.read_bytes()[: full.stat().st_size // 2])
    text = problems_of(lambda: read_mf4(cut))
    assert text.count("damaged MDF file") == 1, text
    assert f"{cut}: damaged MDF file (refused before parsing): a link" in text, text
    assert "truncated?" in text, text


def test_damaged_mf4_structure_is_refused_before_parsing(tmp_path):
    # A damaged channel byte offset made asammdf read outside its buffer (segfault).
    full = write_mf4(Trace("t", signals()), tmp_path / "full.mf4").read_bytes()
    cn = full.index(b"##CN")
    data = bytearray(full)
    data[cn + 24 + 8 * 8 + 4 : cn + 24 + 8 * 8 + 8] = (1 << 24).to_bytes(4, "little")
    bad = tmp_path / "bad.mf4"
    bad.write_bytes(bytes(data))
    text = problems_of(lambda: read_mf4(bad))
    assert f"{bad}: damaged MDF file (refused before parsing): channel at {cn}: bytes" in text
    assert "outside the" in text and "-byte record" in text
    old = bytearray(full)
    old[8:16] = b"3.30    "
    (tmp_path / "v3.mf4").write_bytes(bytes(old))
    assert "MDF version '3.30' is not supported (MDF 4.x only)" in problems_of(
        lambda: read_mf4(tmp_path / "v3.mf4")
    )


# -- manifest --------------------------------------------------------------------------------


def test_unknown_manifest_keys_and_missing_files(tmp_path):
    ds = Dataset([Trace("a", signals(), meta={"ramp": "fast"})])
    root = save_dataset(ds, tmp_path / "ds")
    for copy in ("b.csv", "c.csv"):
        (root / copy).write_bytes((root / "a.csv").read_bytes())
    manifest = {
        "experiment_notes": "free metadata is fine",
        "chanel_map": "m.toml",
        "experiments": [
            {"file": "a.csv", "Ramp": "fast", "ramp": "fast"},
            {"file": "b.csv", "ramp": "slow", "dither_freq": 50},
            {"file": "gone.csv", "ramp": "slow"},
            {"file": "c.csv", "ramp": "x", "dither_waveform": "saw", "dither_freq_Hz": -1},
        ],
    }
    (root / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(DataError) as info:
        load_dataset(root)
    text = str(info.value)
    assert str(root / "manifest.json") in text
    for fragment in (
        "unknown manifest key 'chanel_map' (did you mean 'channel_map'?)",
        "experiments[0]: unknown manifest key 'Ramp' (did you mean 'ramp'?)",
        "experiments[1]: unknown manifest key 'dither_freq' (did you mean 'dither_freq_Hz'?)",
        f"experiments[2]: file 'gone.csv' not found ({root / 'gone.csv'})",
        "experiments[3]: 'dither_freq_Hz' must be a number > 0 (Hz), got -1",
        "experiments[3]: 'dither_waveform' must be one of sine, triangle, square, got 'saw'",
    ):
        assert fragment in text, fragment
    assert "experiment_notes" not in text
    assert len(info.value.problems) == 6


# -- sample rate vs dither ---------------------------------------------------------------------


def test_sample_rate_too_low_for_the_dither(tmp_path):
    sig = signals(n=100, rate=400.0)  # 400 Hz < 10 × 50 Hz
    path = write_raw_csv(tmp_path / "slow.csv", sig)
    text = problems_of(lambda: read_csv(path))
    assert (
        f"{path}: column 'dither_freq_Hz': sample rate 400 Hz is too low to resolve a dither of "
        "50 Hz at line 2 (data row 1)" in text
    )
    assert "at least 10 × the dither frequency (500 Hz)" in text
    del sig["dither_freq_Hz"]
    path = write_raw_csv(tmp_path / "slow2.csv", sig)
    with pytest.raises(DataError) as info:
        read_csv(path, meta={"ramp": "fast", "dither_freq_Hz": 70})
    assert f"{path}: manifest 'dither_freq_Hz': sample rate 400 Hz is too low" in str(info.value)


def test_resampling_below_the_dither_of_a_log_without_its_frequency(tmp_path):
    # A log with the measured current only and no dither frequency anywhere: asked for
    # 100 Hz (`data convert --rate 100`), it was resampled and written with its 50 Hz dither
    # aliased, and `data check` said OK. The dither is demodulated from the current at its
    # own rate, and the sample rate is checked against it as against a given frequency.
    sig = signals(n=2000, rate=1000.0)
    del sig["dither_freq_Hz"]
    path = write_raw_csv(tmp_path / "own.csv", sig)
    read_csv(path)  # at its own 1 kHz it reads
    text = problems_of(lambda: read_log(path, options=ReadOptions(rate_Hz=100.0)))
    assert (
        f"{path}: column 'current_mA': its dither (demodulated, no dither_freq_Hz given): "
        "sample rate 100 Hz is too low to resolve a dither of 50 Hz" in text
    ), text
    trace, _ = read_log(path, options=ReadOptions(rate_Hz=500.0))  # 10 × 50 Hz: fine
    assert trace.sample_rate_Hz == pytest.approx(500.0)


# -- everything at once ------------------------------------------------------------------------


def test_every_problem_of_a_file_in_one_error(tmp_path):
    sig = signals(rate=400.0)
    sig["current_mA"] = sig["current_mA"] / 1000.0
    sig["clutch_pressure_bar"][[5, 6]] = np.nan
    sig["time_s"][30] = sig["time_s"][29]
    sig["oil_temp_C"][40] = 999.0
    path = write_raw_csv(tmp_path / "all.csv", sig)
    with pytest.raises(DataError) as info:
        read_csv(path)
    problems = info.value.problems
    assert len(problems) == 5, problems
    assert all(p.startswith(f"{path}: column ") for p in problems)
    assert [p.split(": ")[1] for p in problems] == [
        "column 'time_s'",  # duplicate time stamp at line 32
        "column 'current_mA'",  # looks like amperes
        "column 'clutch_pressure_bar'",  # NaN run, lines 7-8
        "column 'oil_temp_C'",  # 999 °C at line 42
        "column 'dither_freq_Hz'",  # 400 Hz < 10 × 50 Hz
    ]


def test_validate_trace_in_memory():
    sig = signals()
    sig["clutch_pressure_bar"][3] = np.nan
    problems = validate_trace(Trace("mem", sig))
    assert problems == [
        "trace 'mem': column 'clutch_pressure_bar': missing values (NaN/inf) at row 4 (1 × NaN)"
    ]
    assert validate_trace(Trace("ok", signals())) == []


def test_two_files_with_one_stem_are_named_with_the_remedy(tmp_path):
    # Logs kept per day (day1/r5s.csv, day2/r5s.csv) share a stem, the experiment name; the
    # error named neither file nor what to do.
    root = tmp_path / "ds"
    for day in ("day1", "day2"):
        (root / day).mkdir(parents=True)
        write_raw_csv(root / day / "r5s.csv", signals())
    entries = [{"file": f"{d}/r5s.csv", "ramp": "fast"} for d in ("day1", "day2")]
    (root / "manifest.json").write_text(json.dumps({"experiments": entries}))
    text = problems_of(lambda: load_dataset(root))
    assert (
        f"experiments[1]: experiment name 'r5s' (file stem of {root / 'day2' / 'r5s.csv'}) "
        f"already used by experiments[0] ({root / 'day1' / 'r5s.csv'}); experiments are named "
        "by their file's stem, so rename one of the files" in text
    ), text


def test_a_clutch_pressure_far_below_line_pressure_gets_a_unit_note(tmp_path):
    # A psi channel declared as kPa in the channel map reads 6.9× low: 0.05 – 2.6 bar on a
    # ramp to 1180 mA, and data check said OK.
    n = 4000
    t = np.arange(n) * 1e-3
    current = np.interp(t, [0.0, 2.0, 4.0], [0.0, 1150.0, 0.0])
    pressure = np.clip(current / 60.0, 0.5, 17.7)  # latched to line above ~1060 mA
    sig = signals(n=n, current_mA=current, clutch_pressure_bar=pressure)
    sig["line_pressure_bar"] = np.full(n, 17.7)
    ok = write_raw_csv(tmp_path / "ok.csv", sig)
    _, report = read_log(ok)
    assert not [m for m in report.notes if "clutch pressure reaches" in m], report.notes
    sig["clutch_pressure_bar"] = pressure * 14.5038 / 100.0  # psi, read as kPa
    low = write_raw_csv(tmp_path / "low.csv", sig)
    _, report = read_log(low)
    (note,) = [m for m in report.notes if "clutch pressure reaches" in m]
    assert note.startswith("clutch pressure reaches at most 2.57 bar, 15 % of the line pressure")
    assert "check the clutch pressure's unit" in note
    sig["current_mA"] = current * 0.5  # never above 1000 mA: need not have latched
    _, report = read_log(write_raw_csv(tmp_path / "half.csv", sig))
    assert not [m for m in report.notes if "clutch pressure reaches" in m], report.notes
