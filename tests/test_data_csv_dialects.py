"""CSV logs separated by semicolons or tabs, with a decimal comma: the export of a data
logger or a spreadsheet in a German or French locale (``Zeit;I_soll;P_K`` / ``0,001;250,0``).

Before: refused as "one column 'time_s;current_mA;…'; the file must be comma-separated".
"""

from __future__ import annotations

import numpy as np
import pytest

from clutchlab.data import Trace, read_csv, write_csv
from clutchlab.data.check import check_path
from clutchlab.data.io_csv import CsvDialect, decode_csv
from clutchlab.errors import DataError


@pytest.fixture
def canonical(tmp_path):
    """A canonical comma-separated log and the trace it holds."""
    rng = np.random.default_rng(3)
    n = 400
    t = np.arange(n) * 1e-3
    tr = Trace(
        "run",
        {
            "time_s": t,
            "current_cmd_mA": np.interp(t, [0, 0.1, 0.3, 0.4], [0, 0, 900, 0]),
            "clutch_pressure_bar": rng.uniform(0.0, 17.0, n),
            "line_pressure_bar": rng.normal(17.7, 0.2, n),
        },
        meta={"ramp": "fast"},
    )
    return write_csv(tr, tmp_path / "comma.csv"), tr


def _as_dialect(src, dst, sep: str, decimal: str):
    """``src`` rewritten with separator ``sep`` and decimal mark ``decimal``."""
    lines = src.read_text(encoding="utf-8").splitlines()
    out = [lines[0].replace(",", sep)]
    for line in lines[1:]:
        cells = line.split(",")
        out.append(sep.join(c.replace(".", decimal) for c in cells))
    dst.write_text("\n".join(out) + "\n", encoding="utf-8")
    return dst


@pytest.mark.parametrize(
    ("sep", "decimal", "described"),
    [
        (";", ",", "semicolon-separated, decimal comma"),
        (";", ".", "semicolon-separated, decimal point"),
        ("\t", ",", "tab-separated, decimal comma"),
        ("\t", ".", "tab-separated, decimal point"),
    ],
)
def test_a_locale_export_reads_as_the_comma_separated_log(
    canonical, tmp_path, sep, decimal, described
):
    src, tr = canonical
    path = _as_dialect(src, tmp_path / "locale.csv", sep, decimal)
    back = read_csv(path, meta={"ramp": "fast"})
    for name in tr.signals:
        np.testing.assert_array_equal(back.get(name), read_csv(src).get(name), err_msg=name)
    raw = decode_csv(path)
    assert raw.notes == [f"{path}: read as {described}"]
    result = check_path(path)  # data check says how the file was read
    notes = result.to_dict()["experiments"][0]["notes"]
    assert result.ok and any(described in note for note in notes)


def test_a_comma_separated_log_is_read_as_before_without_a_note(canonical):
    src, _ = canonical
    assert decode_csv(src).notes == []
    assert CsvDialect().describe() == "comma-separated, decimal point"


def test_an_unparseable_cell_of_a_decimal_comma_log_is_named_by_line(canonical, tmp_path):
    src, _ = canonical
    path = _as_dialect(src, tmp_path / "bad.csv", ";", ",")
    lines = path.read_text(encoding="utf-8").splitlines()
    cells = lines[3].split(";")
    cells[2] = "3,5x"  # clutch_pressure_bar of data row 3
    lines[3] = ";".join(cells)
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    with pytest.raises(DataError) as info:
        read_csv(path)
    text = str(info.value)
    assert "unparseable number at line 4 (data row 3) '3,5x'" in text
    assert "line 5" not in text  # the other decimal-comma cells parse


def test_short_and_long_rows_of_a_semicolon_log_are_named(canonical, tmp_path):
    src, _ = canonical
    path = _as_dialect(src, tmp_path / "short.csv", ";", ",")
    lines = path.read_text(encoding="utf-8").splitlines()
    lines[5] = ";".join(lines[5].split(";")[:-1])  # a value missing on line 6
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    with pytest.raises(DataError, match=r"fewer fields than the 4 columns of the header at line 6"):
        read_csv(path)
    lines[5] = lines[5] + ";1,0;2,0"  # now one too many
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    with pytest.raises(DataError, match=r"line 6, saw 5"):  # as in a comma-separated log
        read_csv(path)


def test_a_windows_1252_spreadsheet_export_is_read_with_a_note(canonical, tmp_path):
    # Excel's "CSV (semicolon-separated)" on a German Windows writes Windows-1252: the
    # header "T_Öl [°C]" was refused as "not a UTF-8 text CSV file (... position 40 ...)".
    src, tr = canonical
    lines = _as_dialect(src, tmp_path / "x.csv", ";", ",").read_text().splitlines()
    lines[0] += ";T_Öl [°C]"
    lines[1:] = [f"{line};40,5" for line in lines[1:]]
    path = tmp_path / "excel.csv"
    path.write_bytes(("\r\n".join(lines) + "\r\n").encode("cp1252"))
    cmap = {"signals": {"oil_temp_C": "T_Öl"}}
    from clutchlab.data import read_log

    back, report = read_log(path, channel_map=cmap)
    np.testing.assert_array_equal(back.get("current_cmd_mA"), read_csv(src).get("current_cmd_mA"))
    np.testing.assert_array_equal(back.get("oil_temp_C"), np.full(len(tr), 40.5))
    assert f"{path}: read as semicolon-separated, decimal comma, Windows-1252 text (not UTF-8)" in (
        report.notes
    )


def test_a_trailing_separator_column_without_name_or_values_is_ignored(canonical, tmp_path):
    # A logger writing "t;I;P;" / "0,0;250,0;3,5;" (a separator after every field) was
    # refused as "empty column name at position(s) 4"; an unnamed column that holds values
    # is still a problem, with its position and first line.
    src, _ = canonical
    lines = _as_dialect(src, tmp_path / "x.csv", ";", ",").read_text().splitlines()
    path = tmp_path / "trailing.csv"
    path.write_text("".join(f"{line};\n" for line in lines))
    back = read_csv(path)
    np.testing.assert_array_equal(back.get("current_cmd_mA"), read_csv(src).get("current_cmd_mA"))
    n = len(lines[0].split(";"))
    assert f"{path}: column(s) {n + 1} without a name and without values ignored" in " ".join(
        decode_csv(path).notes
    )
    # a separator after the header only: the data rows lack the unnamed field; before the
    # unnamed column was read, this said "empty column name"; it must not now say that
    # every line is short
    head_only = tmp_path / "head_only.csv"
    head_only.write_text(lines[0] + ";\n" + "".join(f"{line}\n" for line in lines[1:]))
    back = read_csv(head_only)
    np.testing.assert_array_equal(back.get("current_cmd_mA"), read_csv(src).get("current_cmd_mA"))
    full = tmp_path / "full.csv"
    full.write_text(lines[0] + ";\n" + "".join(f"{line};7\n" for line in lines[1:]))
    with pytest.raises(DataError) as info:
        read_csv(full)
    assert (
        f"{full}: column {n + 1} has no name in the header but holds values (first at line 2 "
        "(data row 1))" in str(info.value)
    )
