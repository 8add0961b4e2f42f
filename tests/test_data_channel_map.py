"""Channel maps (TOML): renaming, unit conversion, defaults, manifest keys, map errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from clutchlab.data import (
    ChannelMap,
    Trace,
    convert_units,
    load_channel_map,
    load_dataset,
    read_csv,
    read_log,
    write_parquet,
)
from clutchlab.errors import DataError

MAP_TOML = """\
description = "stand B logger, CSV export"

[signals]
time_s = { channel = "Time", unit = "ms" }
current_mA = { channel = "I_VFS", unit = "A" }
current_cmd_mA = "I_cmd"
clutch_pressure_bar = { channel = "P_clutch", unit = "kPa" }
line_pressure_bar = { channel = "P_line_abs", unit = "bar", offset = -1.01325 }
oil_temp_C = { channel = "T_oil", unit = "degF" }

[defaults]
prime_pressure_bar = 0.6
dither_freq_Hz = 50.0
"""


def logger_csv(path, n=400):
    """A CSV export in logger units: time in ms, A, kPa, absolute bar, °F, plus extras."""
    t_ms = np.arange(n) * 1.0
    i_ma = 500.0 + 100.0 * np.sin(2 * np.pi * 50.0 * t_ms / 1000.0)
    lines = ["Time,I_VFS,I_cmd,P_clutch,P_line_abs,T_oil,Gear [-]"]
    for k in range(n):
        lines.append(
            f"{t_ms[k]:.3f},{i_ma[k] / 1000:.9g},500,{250 + k * 0.1:.6g},18.71325,"
            f"{140 + k * 0.01:.6g},3"
        )
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return t_ms, i_ma


@pytest.mark.parametrize(
    ("value", "unit", "to", "expected"),
    [
        (1.1, "A", "mA", 1100.0),
        (250.0, "mA", "A", 0.25),
        (1.0, "bar", "bar", 1.0),
        (1770.0, "kPa", "bar", 17.7),
        (1.77, "MPa", "bar", 17.7),
        (100.0, "psi", "bar", 6.894757293),
        (100.0, "psig", "bar", 6.894757293),
        (1500.0, "mbar", "bar", 1.5),
        (212.0, "°F", "°C", 100.0),
        (-40.0, "degF", "degC", -40.0),
        (373.15, "K", "°C", 100.0),
        (2500.0, "ms", "s", 2.5),
        (5.0, "µs", "s", 5e-6),
    ],
)
def test_unit_conversion(value, unit, to, expected):
    assert convert_units(np.array([value]), unit, to)[0] == pytest.approx(expected, rel=1e-9)


def test_unit_conversion_refuses_wrong_dimension_and_unknown_units():
    with pytest.raises(DataError, match="'bar' is a pressure unit; 'mA' needs a current unit"):
        convert_units(np.ones(2), "bar", "mA")
    with pytest.raises(DataError, match="unknown unit 'furlong'"):
        convert_units(np.ones(2), "furlong", "s")


def test_csv_log_through_a_toml_channel_map(tmp_path):
    map_path = tmp_path / "stand_b.toml"
    map_path.write_text(MAP_TOML, encoding="utf-8")
    t_ms, i_ma = logger_csv(tmp_path / "log.csv")
    trace, report = read_log(tmp_path / "log.csv", channel_map=map_path)
    np.testing.assert_allclose(trace.time_s, t_ms / 1000.0)
    np.testing.assert_allclose(trace.get("current_mA"), i_ma, rtol=1e-8)
    np.testing.assert_allclose(trace.get("current_cmd_mA"), 500.0)
    np.testing.assert_allclose(trace.get("clutch_pressure_bar"), 2.5 + np.arange(400) * 1e-3)
    np.testing.assert_allclose(trace.get("line_pressure_bar"), 17.7, rtol=1e-12)
    np.testing.assert_allclose(
        trace.get("oil_temp_C"), (140 + np.arange(400) * 0.01 - 32) * 5 / 9, rtol=1e-9
    )
    np.testing.assert_array_equal(trace.get("prime_pressure_bar"), 0.6)  # default
    np.testing.assert_array_equal(trace.get("dither_freq_Hz"), 50.0)  # default
    assert report.channel_map == str(map_path)
    assert report.defaults == {"prime_pressure_bar": 0.6, "dither_freq_Hz": 50.0}
    assert report.sources["time_s"] == "column 'Time' [ms → s]"
    assert report.sources["line_pressure_bar"] == "column 'P_line_abs' -1.01325 bar"
    assert any("'Gear'" in note for note in report.notes)  # unmapped channel: ignored, noted


def test_csv_header_units_are_used_when_the_map_gives_none(tmp_path):
    path = tmp_path / "u.csv"
    path.write_text(
        "t [s],I [A],p [kPa]\n0,0.5,100\n0.001,0.6,110\n0.002,0.7,120\n", encoding="utf-8"
    )
    cmap = {"signals": {"time_s": "t", "current_mA": "I", "clutch_pressure_bar": "p"}}
    trace = read_log(path, channel_map=cmap)[0]
    np.testing.assert_allclose(trace.get("current_mA"), [500.0, 600.0, 700.0])
    np.testing.assert_allclose(trace.get("clutch_pressure_bar"), [1.0, 1.1, 1.2])
    # a canonical name with a non-canonical unit needs a map: no silent conversion
    path.write_text("time_s,current_mA [A],clutch_pressure_bar\n0,0.5,1\n0.001,0.6,1\n")
    with pytest.raises(DataError) as info:
        read_csv(path)
    text = str(info.value)
    assert "u.csv: column 'current_mA': is in 'A' but the canonical unit is 'mA'" in text
    assert "declare unit = 'A' in a channel map" in text


def test_parquet_column_name_units_are_used_as_in_a_csv_header(tmp_path):
    """A spreadsheet or logger export to Parquet names its columns ``p [kPa]``: the unit
    in the name is the column's (was: column 'p' not found, and a map naming ``p [kPa]``
    whole read kPa as the map's unit without a word)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = tmp_path / "u.parquet"
    table = pa.table(
        {
            "t [s]": [0.0, 0.001, 0.002],
            "I (A)": [0.5, 0.6, 0.7],
            "p [kPa]": [100.0, 110.0, 120.0],
            "P(clutch)": [1.0, 1.0, 1.0],  # not a unit: stays in the name
        }
    )
    pq.write_table(table, path)
    cmap = {"signals": {"time_s": "t", "current_mA": "I", "clutch_pressure_bar": "p"}}
    trace = read_log(path, channel_map=cmap)[0]
    np.testing.assert_allclose(trace.get("current_mA"), [500.0, 600.0, 700.0])
    np.testing.assert_allclose(trace.get("clutch_pressure_bar"), [1.0, 1.1, 1.2])
    # a map giving another unit than the name's is refused, naming the file's column
    cmap["signals"]["clutch_pressure_bar"] = {"channel": "p", "unit": "bar"}
    with pytest.raises(DataError, match=r"column 'p \[kPa\]'.*'bar'.*'kPa'"):
        read_log(path, channel_map=cmap)
    # two columns that differ only in the unit are named with both headers
    pq.write_table(
        pa.table({"t [s]": [0.0, 0.001], "p [kPa]": [1.0, 2.0], "p [bar]": [1.0, 2.0]}), path
    )
    with pytest.raises(
        DataError, match=r"duplicate column\(s\) 'p' \(columns 'p \[kPa\]', 'p \[bar\]'\)"
    ):
        read_log(path, channel_map={"signals": {"time_s": "t", "clutch_pressure_bar": "p"}})


def test_map_unit_conflicting_with_file_unit(tmp_path):
    n = 50
    t = np.arange(n) * 1e-3
    trace = Trace("x", {"time_s": t, "current_mA": np.full(n, 400.0), "clutch_pressure_bar": t})
    path = write_parquet(trace, tmp_path / "x.parquet")  # field units: s, mA, bar
    cmap = {"signals": {"clutch_pressure_bar": {"channel": "clutch_pressure_bar", "unit": "kPa"}}}
    with pytest.raises(DataError) as info:
        read_log(path, channel_map=cmap)
    assert (
        "x.parquet: column 'clutch_pressure_bar': the channel map says unit 'kPa' but the file "
        "says 'bar'" in str(info.value)
    )


def test_mapped_channel_missing_is_named_with_the_map(tmp_path):
    map_path = tmp_path / "m.toml"
    map_path.write_text(
        '[signals]\nclutch_pressure_bar = "P_CL"\noil_temp_C = "T_oil"\n', encoding="utf-8"
    )
    path = tmp_path / "log.csv"
    path.write_text("time_s,current_mA,P_CL\n0,400,1\n0.001,400,1\n", encoding="utf-8")
    with pytest.raises(DataError) as info:
        read_log(path, channel_map=map_path)
    assert f"log.csv: channel 'T_oil', mapped to oil_temp_C by {map_path}, not found" in str(
        info.value
    )


def test_a_mapped_column_is_not_also_read_under_its_canonical_name(tmp_path):
    # 'current_mA' holds the commanded current: the map says so, and no signal may take it
    # a second time by canonical-name lookup (it would pass the command off as the measurement)
    path = tmp_path / "log.csv"
    rows = [f"{k * 1e-3:.3f},1.0,{400 + k},{380 + k}" for k in range(20)]
    path.write_text("time_s,clutch_pressure_bar,current_mA,I_meas\n" + "\n".join(rows) + "\n")
    trace, report = read_log(path, channel_map={"signals": {"current_cmd_mA": "current_mA"}})
    assert not trace.has("current_mA")
    assert "current_mA" not in report.sources
    assert report.sources["current_cmd_mA"] == "column 'current_mA'"
    assert (
        f"{path}: column 'current_mA' is mapped to current_cmd_mA by channel map, so it is not "
        "also read as current_mA" in report.notes
    )
    # mapping the measured current too gives both, each from its own column
    both = {"signals": {"current_cmd_mA": "current_mA", "current_mA": "I_meas"}}
    trace, report = read_log(path, channel_map=both)
    np.testing.assert_array_equal(trace.get("current_mA") - trace.get("current_cmd_mA"), -20.0)
    assert not any("not also read" in note for note in report.notes)


def test_invalid_map_lists_every_problem(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(
        """\
descripton = "typo"
[signals]
curent_mA = "I"
clutch_pressure_bar = { unit = "bar" }
line_pressure_bar = { channel = "PL", unit = "mA" }
oil_temp_C = { channel = "T", unit = "rankine" }
prime_pressure_bar = { channel = "PP", scale = 0, colour = "red" }
[defaults]
time_s = 0.0
dither_amp_mA = 9999.0
""",
        encoding="utf-8",
    )
    with pytest.raises(DataError) as info:
        load_channel_map(bad)
    problems = info.value.problems
    text = str(info.value)
    assert len(problems) == 9, text
    assert all(p.startswith(str(bad)) for p in problems)
    for fragment in (
        "unknown key 'descripton' (did you mean 'description'?)",
        "signals.curent_mA: unknown canonical signal (did you mean 'current_mA'?)",
        "signals.clutch_pressure_bar: 'channel' (source channel name) is required",
        "signals.line_pressure_bar: unit 'mA' is a current unit; line_pressure_bar needs a "
        "pressure unit",
        "signals.oil_temp_C: unknown unit 'rankine'",
        "signals.prime_pressure_bar: unknown field 'colour'",
        "signals.prime_pressure_bar: 'scale' must be finite and non-zero",
        "defaults.time_s: time_s cannot have a constant default",
        "defaults.dither_amp_mA: 9999.0 mA is outside the plausible range [0, 500] mA",
    ):
        assert fragment in text, fragment
    syntax = tmp_path / "syntax.toml"
    syntax.write_text("[signals]\ncurrent_mA = \n", encoding="utf-8")
    with pytest.raises(DataError, match=r"syntax\.toml: invalid TOML: .*line 2"):
        load_channel_map(syntax)
    with pytest.raises(DataError, match=r"nope\.toml: channel map not found"):
        load_channel_map(tmp_path / "nope.toml")


def test_manifest_channel_map_keys_and_argument_override(tmp_path):
    root = tmp_path / "ds"
    root.mkdir()
    (root / "stand_b.toml").write_text(MAP_TOML, encoding="utf-8")
    (root / "other.toml").write_text(
        MAP_TOML.replace("prime_pressure_bar = 0.6", "prime_pressure_bar = 0.4"), encoding="utf-8"
    )
    logger_csv(root / "a.csv")
    logger_csv(root / "b.csv")
    manifest = {
        "channel_map": "stand_b.toml",
        "site": "Plant 2",
        "experiments": [
            {"file": "a.csv", "ramp": "fast"},
            {"file": "b.csv", "ramp": "slow", "channel_map": "other.toml"},
        ],
    }
    (root / "manifest.json").write_text(json.dumps(manifest), encoding="utf-8")
    ds = load_dataset(root)
    assert ds["a"].get("prime_pressure_bar")[0] == 0.6
    assert ds["b"].get("prime_pressure_bar")[0] == 0.4  # entry key overrides top-level key
    assert "channel_map" not in ds["b"].meta and ds.manifest_extra == {"site": "Plant 2"}
    assert ds.reports["b"].channel_map == str(root / "other.toml")
    override = ChannelMap.from_dict({**_toml(MAP_TOML), "defaults": {"prime_pressure_bar": 0.55}})
    ds = load_dataset(root, channel_map=override)  # the argument wins over the manifest
    assert ds["a"].get("prime_pressure_bar")[0] == ds["b"].get("prime_pressure_bar")[0] == 0.55

    manifest["experiments"][1]["channel_map"] = "missing.toml"
    (root / "manifest.json").write_text(json.dumps(manifest), encoding="utf-8")
    with pytest.raises(DataError, match=r"experiments\[1\]: channel map 'missing.toml' not found"):
        load_dataset(root)


def _toml(text):
    import tomllib

    return tomllib.loads(text)


def test_readme_channel_map_example_is_valid():
    from pathlib import Path

    readme = (Path(__file__).parents[1] / "README.md").read_text(encoding="utf-8")
    section = readme[readme.index("## Test-stand data: formats, channel maps, validation") :]
    block = section[
        section.index("```toml\n") + 8 : section.index("```", section.index("```toml") + 7)
    ]
    cmap = ChannelMap.from_dict(_toml(block))
    assert cmap.signals["time_s"].unit == "ms" and cmap.signals["current_cmd_mA"].channel == "I_cmd"
    assert cmap.signals["line_pressure_bar"].offset == -1.01325
    assert cmap.defaults == {"prime_pressure_bar": 0.5, "dither_freq_Hz": 50.0}
