"""The synthetic stand: realism of its output, truth kept outside the dataset, CLI."""

from __future__ import annotations

import itertools
import json
import subprocess
import sys

import numpy as np
import pytest

from clutchlab.data import dither_period_mean as period_mean
from clutchlab.data import load_dataset

BIN_MA = 25.0


def _branches(trace):
    """Dither-period mean pressure, rising and falling masks, nominal current."""
    i = trace.get("current_cmd_mA")
    n = round(trace.sample_rate_Hz / trace.meta["dither_freq_Hz"])
    p = period_mean(trace.get("clutch_pressure_bar"), n)
    di = np.gradient(i)
    return i, p, di > 0, di < 0


def _hysteresis(trace, lo, hi):
    """Rising minus falling pressure (bar) in 25 mA bins over [lo, hi) mA."""
    i, p, up, dn = _branches(trace)
    edges = np.arange(lo, hi + 1e-9, BIN_MA)
    return np.array(
        [
            p[up & (i >= a) & (i < b)].mean() - p[dn & (i >= a) & (i < b)].mean()
            for a, b in itertools.pairwise(edges)
        ]
    )


def _latch_currents(trace):
    """Nominal currents (mA) where the pressure snaps to line (rising) and leaves it (falling)."""
    i, p, up, dn = _branches(trace)
    near_line = p > trace.get("line_pressure_bar") - 1.0
    on = i[up & near_line].min()
    off = i[dn & near_line].min()
    return on, off


def test_stand_layout_and_metadata(stand_run):
    ds = stand_run.dataset
    assert len(ds) == 9
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


def test_sensor_noise_and_quantization(stand_run):
    trace = stand_run.dataset["slow_30Hz_A"]
    truth = stand_run.true_pressure["slow_30Hz_A"]
    p = trace.get("clutch_pressure_bar")
    hold = trace.time_s < 0.9  # 0 mA hold: truth is flat, what varies is noise
    assert np.std(p[hold] - truth[hold]) >= 0.02
    steps = np.diff(np.unique(p))
    assert np.min(steps) == pytest.approx(0.01, abs=1e-9)


def test_hysteresis_bands_above_600_mA_ordered_by_ramp_rate(stand_run):
    """Above 600 mA (and below the earliest latch-off) fast, medium, slow form three bands.

    Hysteresis = rising − falling pressure (negative: rising lags). Each band must be
    separated from the next by ≥ 0.1 bar in every 25 mA bin (4× the pressure noise σ).
    """
    ds = stand_run.dataset
    for tag in ("30Hz_A", "50Hz_B", "70Hz_C"):
        traces = {r: ds[f"{r}_{tag}"] for r in ("fast", "medium", "slow")}
        hi = min(_latch_currents(t)[1] for t in traces.values()) - 2 * BIN_MA
        assert hi >= 650, "the regulated band above 600 mA must exist"
        width = {r: -_hysteresis(t, 600.0, hi) for r, t in traces.items()}
        assert np.all(width["slow"] > 0)
        assert np.all(width["fast"] - width["medium"] >= 0.1), tag
        assert np.all(width["medium"] - width["slow"] >= 0.1), tag


def test_latch_on_above_latch_off_and_latched_pressure_is_line(stand_run):
    for trace in stand_run.dataset:
        on, off = _latch_currents(trace)
        assert on > off + 50.0, trace.name
        i, p, _, _ = _branches(trace)
        hold = i >= 1099.9
        line = trace.get("line_pressure_bar")
        assert np.max(np.abs(p[hold][50:-50] - line[hold][50:-50])) <= 0.3, trace.name


def test_near_linear_regulated_rise(stand_run):
    """Between 250 and 700 mA the slow rising branch is a straight line within 0.25 bar."""
    i, p, up, _ = _branches(stand_run.dataset["slow_50Hz_B"])
    sel = up & (i > 250) & (i < 700)
    coef = np.polyfit(i[sel], p[sel], 1)
    assert 10.0 < coef[0] * 1000 < 30.0  # bar/A
    assert np.max(np.abs(np.polyval(coef, i[sel]) - p[sel])) < 0.25


def test_stand_is_reproducible_with_its_seed():
    from clutchlab.physics.stand import DitherSetting, RampProfile, StandConfig, run_stand

    cfg = dict(settings=(DitherSetting(50.0, "A"),), ramps=(RampProfile("fast", 1.0, 0.3),))
    a = run_stand(StandConfig(seed=7, **cfg), progress=False).dataset[0]
    b = run_stand(StandConfig(seed=7, **cfg), progress=False).dataset[0]
    c = run_stand(StandConfig(seed=8, **cfg), progress=False).dataset[0]
    p = "clutch_pressure_bar"
    assert np.array_equal(a.get(p), b.get(p))
    assert not np.array_equal(a.get(p), c.get(p))


def _clutchlab(*args, check=True):
    return subprocess.run(
        [sys.executable, "-m", "clutchlab.cli", *args],
        capture_output=True,
        text=True,
        check=check,
        timeout=600,
    )


def test_cli_stand_writes_dataset_png_and_truth_beside(tmp_path):
    out = tmp_path / "stand"
    res = _clutchlab("stand", "--out", str(out), "--settings", "3", "--quiet")
    assert "wrote 9 experiments" in res.stdout
    ds = load_dataset(out)
    assert len(ds) >= 9
    assert (out / "manifest.json").exists()
    png = out / "pressure_vs_current.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    truth = json.loads((tmp_path / "stand.truth.json").read_text())
    assert set(truth["effects"]) == {"stribeck_friction", "flow_force", "sensor_lag"}
    assert truth["parameters"]["reg_F_c"]["value"] != 1.0
    # Nothing inside the dataset folder reveals the truth.
    inside = " ".join(p.read_text(errors="ignore") for p in out.iterdir() if p.suffix != ".png")
    for word in ("stribeck", "flow_force", "sensor_lag", "reg_F_c", "truth"):
        assert word not in inside


def test_cli_stand_with_effects_and_unknown_effect(tmp_path):
    out = tmp_path / "fx"
    _clutchlab(
        "stand",
        "--out",
        str(out),
        "--settings",
        "1",
        "--quiet",
        "--no-builtin",
        "--effects",
        "sensor_lag,flow_force",
        "--seed",
        "3",
    )
    truth = json.loads((tmp_path / "fx.truth.json").read_text())
    assert truth["effects"] == ["sensor_lag", "flow_force"] and truth["seed"] == 3
    bad = _clutchlab(
        "stand", "--out", str(tmp_path / "bad"), "--effects", "sensor_lagg", check=False
    )
    assert bad.returncode != 0
    assert "unknown effect 'sensor_lagg'" in bad.stderr
    assert "transport_delay" in bad.stderr and "flow_force" in bad.stderr
    assert not (tmp_path / "bad").exists()
