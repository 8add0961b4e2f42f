"""Realism checks of a stand-like dataset, shared by the stand's and the zoo's tests.

Each check asserts one property a transmission engineer recognises in a clutch
pressure-vs-current log: regulated rise, rate-ordered hysteresis bands, latch snap and
release, latched pressure at line, bench signals in range.
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from clutchlab.data import dither_period_mean as period_mean

BIN_MA = 25.0


def branches(trace):
    """Dither-period mean pressure, rising and falling masks, nominal current."""
    i = trace.get("current_cmd_mA")
    n = round(trace.sample_rate_Hz / trace.meta["dither_freq_Hz"])
    p = period_mean(trace.get("clutch_pressure_bar"), n)
    di = np.gradient(i)
    return i, p, di > 0, di < 0


def hysteresis(trace, lo, hi):
    """Rising minus falling pressure (bar) in 25 mA bins over [lo, hi) mA."""
    i, p, up, dn = branches(trace)
    edges = np.arange(lo, hi + 1e-9, BIN_MA)
    return np.array(
        [
            p[up & (i >= a) & (i < b)].mean() - p[dn & (i >= a) & (i < b)].mean()
            for a, b in itertools.pairwise(edges)
        ]
    )


def latch_currents(trace):
    """Nominal currents (mA) where the pressure snaps to line (rising) and leaves it (falling)."""
    i, p, up, dn = branches(trace)
    near_line = p > trace.get("line_pressure_bar") - 1.0
    on = i[up & near_line].min()
    off = i[dn & near_line].min()
    return on, off


def check_layout(ds):
    """27-experiment protocol layout, signals present, bench signals in range."""
    assert ds.ramps == ["fast", "medium", "slow"]
    for trace in ds:
        assert trace.sample_rate_Hz == pytest.approx(1000.0)
        assert {
            "current_mA",
            "current_cmd_mA",
            "dither_amp_mA",
            "dither_freq_Hz",
            "clutch_pressure_bar",
            "line_pressure_bar",
            "prime_pressure_bar",
            "oil_temp_C",
        } <= set(trace.signals)
        i = trace.get("current_cmd_mA")
        assert i[0] == 0 and i.max() == pytest.approx(1100) and i[-1] == 0
        assert 0 <= trace.get("dither_amp_mA").max() <= 225
        assert 30 <= trace.meta["dither_freq_Hz"] <= 70
        line = trace.get("line_pressure_bar")
        prime = trace.get("prime_pressure_bar")
        assert 17.35 <= line.min() and line.max() <= 18.05 and line.std() > 0.02
        assert 0.35 <= prime.min() and prime.max() <= 0.65 and prime.std() > 0.005
    shapes = {t.meta["dither_shape"] for t in ds}
    assert len(shapes) >= 3


def check_hysteresis_bands(ds, tags=("30Hz_A", "50Hz_B", "70Hz_C")):
    """Above 600 mA (and below the earliest latch-off) fast, medium, slow form three bands.

    Hysteresis = rising − falling pressure (negative: rising lags). Each band must be
    separated from the next by ≥ 0.1 bar in every 25 mA bin (4× the pressure noise σ).
    """
    for tag in tags:
        traces = {r: ds[f"{r}_{tag}"] for r in ("fast", "medium", "slow")}
        hi = min(latch_currents(t)[1] for t in traces.values()) - 2 * BIN_MA
        assert hi >= 650, "the regulated band above 600 mA must exist"
        width = {r: -hysteresis(t, 600.0, hi) for r, t in traces.items()}
        assert np.all(width["slow"] > 0)
        assert np.all(width["fast"] - width["medium"] >= 0.1), tag
        assert np.all(width["medium"] - width["slow"] >= 0.1), tag


def check_latch(ds):
    """Latch-on current above latch-off by > 50 mA; latched pressure is line within 0.3 bar."""
    for trace in ds:
        on, off = latch_currents(trace)
        assert on > off + 50.0, trace.name
        i, p, _, _ = branches(trace)
        hold = i >= 1099.9
        line = trace.get("line_pressure_bar")
        assert np.max(np.abs(p[hold][50:-50] - line[hold][50:-50])) <= 0.3, trace.name


def check_linear_rise(trace):
    """Between 250 and 700 mA the slow rising branch is a straight line within 0.25 bar."""
    i, p, up, _ = branches(trace)
    sel = up & (i > 250) & (i < 700)
    coef = np.polyfit(i[sel], p[sel], 1)
    assert 10.0 < coef[0] * 1000 < 30.0  # bar/A
    assert np.max(np.abs(np.polyval(coef, i[sel]) - p[sel])) < 0.25
