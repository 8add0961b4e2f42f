"""MATLAB ``.mat`` logs (issue 19, must-show 2): v7 and v7.3 files written here in MATLAB's
layout round-trip through ``load_dataset`` / ``save_dataset`` within float32, are read through
channel maps, and bad input is refused with file, variable and row."""

from __future__ import annotations

import json
import re

import h5py
import numpy as np
import pytest
import scipy.io

from clutchlab.data import load_dataset, read_log, save_dataset, write_mat73
from clutchlab.errors import DataError
from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, run_stand


@pytest.fixture(scope="module")
def stand():
    return run_stand(
        StandConfig(
            settings=(DitherSetting(50.0, "B"),),
            ramps=(RampProfile("fast", 1.0, 0.2), RampProfile("medium", 2.0, 0.2)),
        ),
        progress=False,
    ).dataset


def assert_same(a, b):
    assert list(b.signals) == list(a.signals)
    for name in a.signals:
        np.testing.assert_allclose(b.get(name), a.get(name), rtol=1e-6, atol=1e-6, err_msg=name)


def h5_matlab_double(group, name, values):
    """A MATLAB N×1 double as MATLAB v7.3 stores it (HDF5 holds the 1×N transpose)."""
    ds = group.create_dataset(name, data=np.asarray(values, dtype=float).reshape(1, -1))
    ds.attrs["MATLAB_class"] = np.bytes_("double")


def write_matlab_v73(path, struct_name, fields):
    """What ``save(path, struct_name, '-v7.3')`` writes for a struct of column vectors."""
    with h5py.File(path, "w", userblock_size=512) as f:
        g = f.create_group(struct_name)
        g.attrs["MATLAB_class"] = np.bytes_("struct")
        for name, values in fields.items():
            h5_matlab_double(g, name, values)
    head = b"MATLAB 7.3 MAT-file, Platform: GLNXA64, Created on: Mon Nov 23 10:00:00 2026"
    with open(path, "r+b") as fh:
        fh.write((head.ljust(116, b" ") + b"\0" * 8 + b"\x00\x02IM").ljust(512, b"\0"))


def test_v7_dataset_round_trip(stand, tmp_path):
    folder = save_dataset(stand, tmp_path / "mat", format="mat")
    assert sorted(p.suffix for p in folder.glob("*_*")) == [".mat", ".mat"]
    assert scipy.io.matlab.matfile_version(str(folder / "fast_50Hz_B.mat"))[0] == 1
    back = load_dataset(folder)
    assert back.names == stand.names
    for a, b in zip(stand, back, strict=True):
        assert_same(a, b)
        assert b.meta == a.meta
    # and on to CSV and back: the same within float32
    again = load_dataset(save_dataset(back, tmp_path / "csv", format="csv"))
    for a, b in zip(stand, again, strict=True):
        assert_same(a, b)


def test_v73_dataset_round_trip(stand, tmp_path):
    folder = tmp_path / "mat73"
    folder.mkdir()
    entries = []
    for tr in stand:
        write_mat73(
            tr, folder / f"{tr.name}.mat", struct="run" if tr.meta["ramp"] == "fast" else None
        )
        entries.append({"file": f"{tr.name}.mat", **tr.meta})
    (folder / "manifest.json").write_text(json.dumps({"experiments": entries}))
    back = load_dataset(folder)
    for a, b in zip(stand, back, strict=True):
        assert_same(a, b)
    assert scipy.io.matlab.matfile_version(str(folder / "fast_50Hz_B.mat"))[0] == 2


def test_matlab_layouts_through_a_channel_map(stand, tmp_path):
    tr = stand[0]
    fields = {
        "t": tr.time_s,
        "I_sol": tr.get("current_mA") / 1000.0,  # A
        "P_CL": tr.get("clutch_pressure_bar") * 100.0,  # kPa
    }
    cmap = {
        "signals": {
            "time_s": "t",
            "current_mA": {"channel": "I_sol", "unit": "A"},
            "clutch_pressure_bar": {"channel": "P_CL", "unit": "kPa"},
        },
        "defaults": {"dither_freq_Hz": 50.0},
    }
    write_matlab_v73(tmp_path / "v73.mat", "exp", fields)
    # v7: one variable per channel, MATLAB row vectors, and a logged scalar set point
    scipy.io.savemat(tmp_path / "v7.mat", {**fields, "f_dither": 50.0}, oned_as="row")
    for name in ("v73.mat", "v7.mat"):
        got = read_log(tmp_path / name, channel_map=cmap)[0]
        np.testing.assert_allclose(got.get("current_mA"), tr.get("current_mA"), rtol=1e-9)
        np.testing.assert_allclose(
            got.get("clutch_pressure_bar"), tr.get("clutch_pressure_bar"), rtol=1e-9, atol=1e-12
        )


def test_bad_mat_files_name_file_variable_and_row(stand, tmp_path):
    tr = stand[0]
    good = {n: tr.get(n) for n in ("time_s", "current_mA", "clutch_pressure_bar")}
    p = good["clutch_pressure_bar"].copy()
    p[100:103] = np.nan
    path = tmp_path / "nan.mat"
    scipy.io.savemat(path, {**good, "clutch_pressure_bar": p, "dither_freq_Hz": 50.0})
    with pytest.raises(DataError) as exc:
        read_log(path)
    text = str(exc.value)
    assert str(path) in text and "variable 'clutch_pressure_bar'" in text and "row 101" in text

    short = tmp_path / "short.mat"
    scipy.io.savemat(short, {**good, "current_mA": good["current_mA"][:-5]})
    with pytest.raises(DataError, match=r"variable 'current_mA': \d+ samples where the other"):
        read_log(short)

    matrix = tmp_path / "matrix.mat"
    scipy.io.savemat(matrix, {**good, "P_all": np.ones((len(p), 3)), "dither_freq_Hz": 50.0})
    with pytest.raises(DataError, match=r"variable 'P_all'.*matrix"):
        read_log(matrix, channel_map={"signals": {"clutch_pressure_bar": "P_all"}})

    two = tmp_path / "two.mat"
    write_matlab_v73(two, "a", good)
    with h5py.File(two, "a") as f:
        g = f.create_group("b")
        g.attrs["MATLAB_class"] = np.bytes_("struct")
        h5_matlab_double(g, "x", [1.0, 2.0])
    with pytest.raises(DataError, match=r"2 structs \(a, b\)"):
        read_log(two)

    for name, data in (("junk.mat", b"not a mat file at all" * 20), ("empty.mat", b"")):
        (tmp_path / name).write_bytes(data)
        with pytest.raises(DataError, match=re.escape(name)):
            read_log(tmp_path / name)
    for src in ("nan.mat", "two.mat"):  # v7 and v7.3
        truncated = tmp_path / f"truncated_{src}"
        truncated.write_bytes((tmp_path / src).read_bytes()[:700])
        with pytest.raises(DataError, match=re.escape(truncated.name)):
            read_log(truncated)


MAT_MAP = {
    "signals": {
        "time_s": "t",
        "current_mA": {"channel": "I_sol", "unit": "A"},
        "clutch_pressure_bar": {"channel": "P_CL", "unit": "kPa"},
    },
    "defaults": {"dither_freq_Hz": 50.0},
}


def logger_fields(tr):
    """A trace's channels as a logger names them: t (s), I_sol (A), P_CL (kPa)."""
    return {
        "t": tr.time_s,
        "I_sol": tr.get("current_mA") / 1000.0,
        "P_CL": tr.get("clutch_pressure_bar") * 100.0,
    }


def test_unused_variable_of_another_length_is_ignored(stand, tmp_path):
    # a 10 Hz temperature next to the 1 kHz vectors: the map does not use it, so its length
    # does not matter; once the map uses it, the mismatch is an error naming the file
    tr = stand[0]
    slow = np.full(30, 60.0)
    v73 = tmp_path / "v73.mat"
    write_matlab_v73(v73, "run", {**logger_fields(tr), "T": slow})
    v7 = tmp_path / "v7.mat"
    scipy.io.savemat(v7, {**logger_fields(tr), "T": slow})
    for path, label in ((v73, "run.T"), (v7, "T")):
        got, report = read_log(path, channel_map=MAT_MAP)
        np.testing.assert_allclose(got.get("current_mA"), tr.get("current_mA"), rtol=1e-9)
        assert any("ignored: 'T'" in note for note in report.notes)
        with_t = {"signals": {**MAT_MAP["signals"], "oil_temp_C": "T"}}
        with pytest.raises(DataError) as info:
            read_log(path, channel_map=with_t)
        expected = f"{path}: variable {label!r}: 30 samples where the other vectors have"
        assert any(p.startswith(expected) for p in info.value.problems), info.value.problems


def test_struct_next_to_a_scalar_variable(stand, tmp_path):
    # MATLAB save('run.mat', 'run', 'f_dither'): the struct is the experiment, the scalar a
    # constant channel next to it
    tr = stand[0]
    v73 = tmp_path / "v73.mat"
    write_matlab_v73(v73, "run", logger_fields(tr))
    with h5py.File(v73, "a") as f:
        h5_matlab_double(f, "f_dither", [50.0])
    v7 = tmp_path / "v7.mat"
    scipy.io.savemat(v7, {"run": logger_fields(tr), "f_dither": 50.0})
    with_f = {"signals": {**MAT_MAP["signals"], "dither_freq_Hz": "f_dither"}}
    for path in (v73, v7):
        got, report = read_log(path, channel_map=with_f)
        np.testing.assert_allclose(got.get("current_mA"), tr.get("current_mA"), rtol=1e-9)
        np.testing.assert_array_equal(got.get("dither_freq_Hz"), 50.0)
        assert "variable 'f_dither' is a scalar (50): used as a constant channel" in report.notes
        got, report = read_log(path, channel_map=MAT_MAP)  # not mapped: ignored
        assert report.sources["current_mA"].startswith("variable 'run.I_sol'")
        assert any("ignored: 'f_dither'" in note for note in report.notes)
    # a scalar named like one of the struct's fields does not replace it
    clash = tmp_path / "clash.mat"
    scipy.io.savemat(clash, {"run": logger_fields(tr), "t": 5.0})
    got, report = read_log(clash, channel_map=MAT_MAP)
    np.testing.assert_array_equal(got.time_s, tr.time_s)
    assert "variable 't' ignored: struct 'run' has a field of that name" in report.notes
