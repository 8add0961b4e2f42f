"""Tests of the canonical signals, Trace and Dataset types (in memory, no files)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from clutchlab.data import (
    CANONICAL_ORDER,
    SIGNALS,
    Dataset,
    SignalSpec,
    Trace,
    unit_of,
)
from clutchlab.errors import DataError


def make_trace(name: str = "fast_30Hz_A", n: int = 200, ramp: str | None = "fast", **extra):
    """A small trace sampled at 1 kHz with a triangular current ramp."""
    t = np.arange(n) * 1e-3
    current = 1100.0 * (1.0 - np.abs(2.0 * t / t[-1] - 1.0))
    signals = {
        "time_s": t,
        "current_mA": current + 50.0 * np.sin(2 * np.pi * 30.0 * t),
        "clutch_pressure_bar": 0.01 * current,
        **extra,
    }
    meta = {"ramp": ramp, "dither_freq_Hz": 30, "dither_shape": "A"} if ramp else {}
    return Trace(name, signals, meta=meta)


# -- signals ------------------------------------------------------------------------------


def test_signals_table_matches_design():
    assert CANONICAL_ORDER == (
        "time_s",
        "current_mA",
        "current_cmd_mA",
        "dither_amp_mA",
        "dither_freq_Hz",
        "clutch_pressure_bar",
        "line_pressure_bar",
        "prime_pressure_bar",
        "oil_temp_C",
    )
    assert all(isinstance(s, SignalSpec) for s in SIGNALS.values())
    assert [n for n, s in SIGNALS.items() if s.required] == ["time_s", "clutch_pressure_bar"]
    assert SIGNALS["line_pressure_bar"].default == 17.7
    assert SIGNALS["prime_pressure_bar"].default == 0.5
    assert SIGNALS["oil_temp_C"].default is None
    assert (SIGNALS["current_mA"].plausible_min, SIGNALS["current_mA"].plausible_max) == (
        -300.0,
        2000.0,
    )
    assert SIGNALS["clutch_pressure_bar"].plausible_max == 60.0
    assert SIGNALS["oil_temp_C"].plausible_min == -40.0
    assert unit_of("oil_temp_C") == "°C"
    assert unit_of("dither_freq_Hz") == "Hz"
    with pytest.raises(DataError, match="current_A"):
        unit_of("current_A")


# -- Trace --------------------------------------------------------------------------------


def test_trace_basics_and_read_only_copies():
    t = np.arange(100) * 0.002
    p = np.linspace(0.0, 5.0, 100)
    tr = Trace("x", {"clutch_pressure_bar": p, "current_cmd_mA": t * 1e3, "time_s": t})
    p[0] = 99.0  # the trace holds a copy
    assert tr.get("clutch_pressure_bar")[0] == 0.0
    assert list(tr.signals) == ["time_s", "current_cmd_mA", "clutch_pressure_bar"]
    assert len(tr) == 100
    assert tr.duration_s == pytest.approx(0.198)
    assert tr.sample_rate_Hz == pytest.approx(500.0)
    assert tr.ramp is None
    assert tr.units == {"time_s": "s", "current_cmd_mA": "mA", "clutch_pressure_bar": "bar"}
    assert tr.has("current_cmd_mA") and not tr.has("current_mA")
    assert tr.time_s.dtype == np.float64
    with pytest.raises(ValueError, match="read-only"):
        tr.time_s[0] = 1.0


def test_get_defaults_for_line_and_prime_pressure():
    tr = make_trace(n=50)
    line = tr.get("line_pressure_bar")
    prime = tr.get("prime_pressure_bar")
    assert line.shape == (50,) and np.all(line == 17.7)
    assert prime.shape == (50,) and np.all(prime == 0.5)
    assert not tr.has("line_pressure_bar")
    assert np.all(tr.get("oil_temp_C", default=80.0) == 80.0)
    # a measured signal wins over the default
    measured = np.full(50, 16.9)
    assert np.all(tr.with_signals(line_pressure_bar=measured).get("line_pressure_bar") == 16.9)
    with pytest.raises(DataError, match=r"'oil_temp_C'.*no default"):
        tr.get("oil_temp_C")
    with pytest.raises(DataError, match="unknown signal 'pressure'"):
        tr.get("pressure")


def test_trace_collects_every_problem():
    with pytest.raises(DataError) as info:
        Trace(
            "bad",
            {
                "time_s": [0.0, 1.0, 1.0, 0.5, 4.0],
                "current_A": [0.1] * 5,
                "dither_amp_mA": [1.0, 2.0],
                "oil_temp_C": np.zeros((5, 2)),
            },
        )
    problems = info.value.problems
    text = str(info.value)
    assert len(problems) == 6, text
    assert "non-canonical column(s) 'current_A'" in text
    assert "did you mean 'current_mA'" in text
    assert "'current_mA' / 'current_cmd_mA' is required" in text
    assert "'clutch_pressure_bar' is missing" in text
    assert "'dither_amp_mA' has 2 samples but 'time_s' has 5" in text
    assert "'oil_temp_C': must be 1-D" in text
    assert "not strictly increasing at row 3, row 4" in text
    assert "trace 'bad'" in problems[0]


def test_trace_rejects_missing_time_and_nan_time():
    with pytest.raises(DataError, match="'time_s' is missing"):
        Trace("a", {"current_mA": [1.0], "clutch_pressure_bar": [1.0]})
    with pytest.raises(DataError, match=r"non-finite value at row 2"):
        Trace(
            "a",
            {"time_s": [0, np.nan, 2], "current_mA": [1, 2, 3], "clutch_pressure_bar": [1, 2, 3]},
        )
    with pytest.raises(DataError, match=r"source\.csv"):
        Trace("a", {"time_s": [0.0]}, source="source.csv")


def test_to_pandas_and_from_pandas_round_trip():
    tr = make_trace(n=30, oil_temp_C=np.full(30, 80.0), line_pressure_bar=np.full(30, 17.5))
    df = tr.to_pandas()
    assert list(df.columns) == [
        "time_s",
        "current_mA",
        "clutch_pressure_bar",
        "line_pressure_bar",
        "oil_temp_C",
    ]
    assert df.attrs["units"]["oil_temp_C"] == "°C"
    assert df.attrs["meta"] == {"ramp": "fast", "dither_freq_Hz": 30, "dither_shape": "A"}
    df.loc[0, "clutch_pressure_bar"] = -5.0  # the DataFrame is a copy
    assert tr.get("clutch_pressure_bar")[0] != -5.0
    back = Trace.from_pandas(tr.to_pandas(), name="copy")
    assert back.name == "copy"
    assert back.meta == tr.meta
    for name in tr.signals:
        np.testing.assert_array_equal(back.get(name), tr.get(name))


def test_from_pandas_rejects_unknown_columns_and_units():
    df = make_trace(n=5).to_pandas()
    df["speed_rpm"] = 1.0
    df["Current_mA"] = 1.0
    with pytest.raises(DataError) as info:
        Trace.from_pandas(df, name="x")
    assert "'speed_rpm'" in str(info.value) and "'Current_mA'" in str(info.value)
    df = make_trace(n=5).to_pandas()
    df.attrs["units"]["current_mA"] = "A"
    with pytest.raises(DataError, match="'current_mA' is in 'A'"):
        Trace.from_pandas(df, name="x")
    with pytest.raises(DataError, match="'clutch_pressure_bar': not numeric"):
        Trace.from_pandas(
            pd.DataFrame({"time_s": [0.0], "current_mA": [1.0], "clutch_pressure_bar": ["x"]}),
            name="x",
        )


def test_with_signals_and_slice_time():
    tr = make_trace(n=100)
    tr2 = tr.with_signals(dither_amp_mA=np.full(100, 50.0))
    assert tr2.has("dither_amp_mA") and not tr.has("dither_amp_mA")
    assert tr2.meta == tr.meta and tr2.name == tr.name
    with pytest.raises(DataError, match="has 3 samples"):
        tr.with_signals(dither_amp_mA=[1.0, 2.0, 3.0])
    part = tr.slice_time(0.010, 0.019)
    assert len(part) == 10
    assert part.time_s[0] == pytest.approx(0.010) and part.time_s[-1] == pytest.approx(0.019)
    np.testing.assert_array_equal(part.get("current_mA"), tr.get("current_mA")[10:20])
    assert len(tr.slice_time(t1=0.0045)) == 5
    with pytest.raises(DataError, match="no sample"):
        tr.slice_time(5.0, 6.0)
    with pytest.raises(DataError, match="invalid time window"):
        tr.slice_time(0.5, 0.1)


def test_resample_onto_a_uniform_grid():
    tr = make_trace(n=101)  # 1 kHz, 0.1 s
    down = tr.resample(250.0)
    assert len(down) == 26 and down.sample_rate_Hz == pytest.approx(250.0)
    np.testing.assert_allclose(down.time_s, np.arange(26) * 4e-3, rtol=0, atol=1e-12)
    np.testing.assert_allclose(down.get("current_mA"), tr.get("current_mA")[::4], atol=1e-9)
    assert down.meta == tr.meta and down.name == tr.name
    up = tr.resample(4000.0)
    assert len(up) == 401
    p = tr.get("clutch_pressure_bar")
    np.testing.assert_allclose(up.get("clutch_pressure_bar"), np.interp(up.time_s, tr.time_s, p))
    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(DataError, match="must be > 0 Hz"):
            tr.resample(bad)
    with pytest.raises(DataError, match="fewer than two samples"):
        tr.resample(5.0)


# -- Dataset ------------------------------------------------------------------------------


def make_dataset() -> Dataset:
    return Dataset(
        [
            make_trace("fast_30Hz_A", ramp="fast"),
            make_trace("medium_30Hz_A", ramp="medium"),
            make_trace("slow_30Hz_A", ramp="slow"),
            make_trace("fast_70Hz_B", ramp="fast"),
        ],
        manifest_extra={"stand": "synthetic"},
    )


def test_dataset_access_and_select():
    ds = make_dataset()
    assert len(ds) == 4
    assert ds.names == ["fast_30Hz_A", "medium_30Hz_A", "slow_30Hz_A", "fast_70Hz_B"]
    assert ds.ramps == ["fast", "medium", "slow"]
    assert ds[1].name == "medium_30Hz_A"
    assert ds["slow_30Hz_A"] is ds[2]
    assert [t.name for t in ds] == ds.names
    train = ds.select(ramps=["fast", "slow"])
    assert train.names == ["fast_30Hz_A", "slow_30Hz_A", "fast_70Hz_B"]
    assert train.manifest_extra == {"stand": "synthetic"}
    assert ds.by_ramp("medium").names == ["medium_30Hz_A"]
    assert ds.select(ramps="fast", names=["fast_70Hz_B", "slow_30Hz_A"]).names == ["fast_70Hz_B"]
    with pytest.raises(DataError, match=r"'turbo'.*known: 'fast', 'medium', 'slow'"):
        ds.select(ramps=["fast", "turbo"])
    with pytest.raises(DataError, match="unknown experiment name"):
        ds.select(names=["nope"])
    with pytest.raises(KeyError, match="nope"):
        ds["nope"]
    # a position out of range, or a key of the wrong type, says what the dataset holds
    # (were Python's bare "tuple index out of range" and "indices must be integers")
    with pytest.raises(IndexError, match=r"position 99 is out of range: the dataset has 4 "):
        ds[99]
    assert ds[-4].name == "fast_30Hz_A" and ds[np.int64(3)].name == "fast_70Hz_B"
    with pytest.raises(TypeError, match=r"name, an integer position or a slice, not float 1\.5"):
        ds[1.5]


def test_dataset_rejects_duplicates_and_builds_manifest():
    with pytest.raises(DataError, match="'a' already used by experiment 0"):
        Dataset([make_trace("a"), make_trace("b"), make_trace("a")])
    manifest = make_dataset().manifest()
    assert manifest["stand"] == "synthetic"
    assert manifest["experiments"][0] == {
        "file": "fast_30Hz_A.csv",
        "ramp": "fast",
        "dither_freq_Hz": 30,
        "dither_shape": "A",
    }
    with pytest.raises(DataError, match=r"'noramp'.*no ramp label"):
        Dataset([make_trace("noramp", ramp=None)]).manifest()


# ---- argument checks of the derived-signal helpers (a new-user session's API findings) -----


def test_pressure_metrics_needs_equal_shapes_before_broadcasting():
    from clutchlab.data import pressure_metrics

    y = np.linspace(0.0, 10.0, 100)
    for predicted in (5.0, [5.0], y[:50]):  # a scalar broadcast to a "fit" before
        with pytest.raises(ValueError, match="same shape"):
            pressure_metrics(y, predicted)


def test_first_order_lag_refuses_bad_arguments():
    from clutchlab.data import first_order_lag

    x = np.linspace(0.0, 1.0, 50)
    for tau, fs in ((float("nan"), 1000.0), (-0.1, 1000.0), (0.1, 0.0), (0.1, -1000.0)):
        with pytest.raises(DataError):
            first_order_lag(x, tau, fs)
    with pytest.raises(DataError, match="non-finite value at row 3"):
        first_order_lag(np.array([0.0, 1.0, np.nan]), 0.1, 1000.0)
    np.testing.assert_array_equal(first_order_lag(x, 0.0, 1000.0), x)


def test_window_and_crossing_lengths_are_checked():
    from clutchlab.data import dither_period_mean, first_crossing

    with pytest.raises(DataError, match="one value or one per sample"):
        dither_period_mean(np.zeros(10), np.full(3, 2.0))
    with pytest.raises(DataError, match="same length"):
        first_crossing(np.arange(3.0), np.array([-1.0, -0.5, 0.5, 1.0]), True)
    with pytest.raises(DataError, match="same length"):
        first_crossing(np.arange(5.0), np.array([-1.0, 1.0]), True)


def test_pressure_metrics_of_a_flat_measurement_has_no_fit_pct_and_no_warning():
    """A measured pressure that does not vary printed numpy's divide warnings (fit % = -inf
    or NaN with a RuntimeWarning); it has no fit % to give."""
    import warnings

    from clutchlab.data import pressure_metrics

    y = np.full(50, 3.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = pressure_metrics(y, y + 0.1)
        exact = pressure_metrics(y, y.copy())
    assert np.isnan(m["fit_pct"]) and np.isnan(exact["fit_pct"])
    assert m["rmse_bar"] == pytest.approx(0.1)
    # a constant pressure whose mean is not exact in binary: a spread of rounding errors gave
    # a fit of about -6e14 % (session 42's ML pass)
    y = np.full(1000, 17.7) + np.where(np.arange(1000) % 2, 2e-15, 0.0)
    assert np.isnan(pressure_metrics(y, y + 0.1)["fit_pct"])
    ramp = np.linspace(0.0, 1e-6, 1000)  # a variation far above the rounding errors counts
    assert np.isfinite(pressure_metrics(ramp, ramp)["fit_pct"])


def test_dither_period_from_a_frequency_logged_as_0_while_the_dither_is_off():
    """A logger writing 0 Hz while the dither is off (here 60 % of the samples) made the
    median frequency 0 and the dither period one sample: the period means then averaged
    nothing. The period comes from the samples where the frequency is logged."""
    from clutchlab.data import dither_period_samples

    n = 2000
    f = np.where(np.arange(n) < 1200, 0.0, 50.0)
    t = np.arange(n) * 1e-3
    tr = Trace(
        "x",
        {
            "time_s": t,
            "current_mA": np.zeros(n),
            "clutch_pressure_bar": np.zeros(n),
            "dither_freq_Hz": f,
        },
    )
    assert dither_period_samples(tr) == pytest.approx(20.0)
    off = Trace("off", dict(tr.signals) | {"dither_freq_Hz": np.zeros(n)})
    assert dither_period_samples(off) == 1.0


def test_read_json_object_is_none_for_anything_but_a_json_object(tmp_path):
    from clutchlab.data import read_json_object

    obj = tmp_path / "o.json"
    obj.write_text('{"kind": "x"}', encoding="utf-8")
    assert read_json_object(obj) == {"kind": "x"}
    assert read_json_object(obj, max_bytes=5) is None  # larger than the limit: not read
    for name, text in (("list.json", "[1]"), ("bad.json", "{"), ("deep.json", "[" * 100000)):
        (tmp_path / name).write_text(text, encoding="utf-8")
        assert read_json_object(tmp_path / name) is None
    assert read_json_object(tmp_path / "missing.json") is None
    assert read_json_object(tmp_path) is None  # a folder
