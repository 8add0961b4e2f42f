"""Signatures that see through a poor base fit (issue 17): what a flexible map of the
current and its direction explains is removed before a signal that moves independently
of the ramp is measured."""

from __future__ import annotations

import numpy as np
import pytest

from clutchlab.validation.discover.diagnostics import (
    SIGNATURE_ETA2,
    current_map_residual,
    diagnose,
    signal_association,
)
from clutchlab.validation.discover.residuals import SIGNALS, ResidualSet

N_EXP, N = 6, 2000


def _residual(line_gain: float, seed: int = 0) -> ResidualSet:
    """Six triangle ramps (0 → 1000 → 0 mA). The residual is a large misfit that repeats
    with the current and its direction (a misplaced hysteresis band, ±0.4 bar), plus
    ``line_gain`` × the line pressure's wander (independent per experiment, ~3 s
    correlation), plus white noise."""
    rng = np.random.default_rng(seed)
    t = np.arange(N) * 0.01
    up = np.arange(N) < N // 2
    cur = np.where(up, t / t[N // 2] * 1000.0, (t[-1] - t) / (t[-1] - t[N // 2]) * 1000.0)
    didt = np.gradient(cur, t)
    sign = np.sign(didt)
    rs, sig = [], {k: [] for k in SIGNALS}
    for _ in range(N_EXP):
        wander = np.zeros(N)
        a = np.exp(-0.01 / 3.0)
        for k in range(1, N):
            wander[k] = a * wander[k - 1] + np.sqrt(1 - a * a) * 0.3 * rng.standard_normal()
        misfit = 0.4 * sign * np.sin(np.pi * cur / 1000.0) + 0.2 * (cur / 1000.0) ** 2
        rs.append(misfit + line_gain * wander + 0.01 * rng.standard_normal(N))
        values = {
            "current_mA": cur,
            "didt_mA_s": didt,
            "didt_sign": sign,
            "pressure_bar": 10.0 * cur / 1000.0,
            "dpdt_bar_s": np.gradient(10.0 * cur / 1000.0, t),
            "line_pressure_bar": 17.7 + wander,
            "oil_temp_C": np.full(N, 40.0),
            "dither_amp_mA": np.full(N, 100.0),
            "dither_freq_Hz": np.full(N, 50.0),
        }
        for k in SIGNALS:
            sig[k].append(values[k])
    n = N_EXP * N
    return ResidualSet(
        r=np.concatenate(rs),
        experiments=[f"e{k}" for k in range(N_EXP)],
        slices=[(k * N, (k + 1) * N) for k in range(N_EXP)],
        signals={k: np.concatenate(v) for k, v in sig.items()},
        time_s=np.tile(t, N_EXP),
        row_dt_s=0.01,
        n_period=1.0,
        keep=np.ones(n, dtype=bool),
    )


def _line(assoc: list[dict]) -> dict:
    return next(a for a in assoc if a["signal"] == "line_pressure_bar")


def test_the_current_map_removes_what_repeats_with_the_ramp():
    res = _residual(line_gain=0.0)
    rest = current_map_residual(res)
    assert rest.shape == res.r.shape
    # the misfit repeats in every experiment: what is left is the noise and the bin width
    assert np.std(rest) < 0.1 * np.std(res.r)
    assert abs(float(np.mean(rest))) < 1e-12


def test_a_line_pressure_coupling_under_a_large_misfit_enters_the_signature():
    res = _residual(line_gain=0.15)
    line = _line(signal_association(res))
    assert line["eta2"] < SIGNATURE_ETA2  # drowned in the misfit on the residual itself
    assert line["eta2_beyond_current"] >= 0.5
    diag = diagnose(res)
    assert "line_pressure_bar" in diag.signature
    assert "beyond the current and its direction" in diag.summary()


def test_no_line_pressure_in_the_signature_when_the_residual_does_not_follow_it():
    res = _residual(line_gain=0.0, seed=1)
    assoc = signal_association(res)
    assert _line(assoc)["eta2_beyond_current"] < SIGNATURE_ETA2
    # the map's own signals are measured on the residual only
    assert all(
        a["eta2_beyond_current"] is None
        for a in assoc
        if a["signal"] in ("current_mA", "didt_mA_s", "didt_sign", "pressure_bar")
    )
    assert "line_pressure_bar" not in diagnose(res).signature


@pytest.mark.parametrize("gain", [0.05, 0.15])
def test_the_share_beyond_the_map_grows_with_the_coupling(gain):
    low = _line(signal_association(_residual(gain / 2, seed=2)))["eta2_beyond_current"]
    high = _line(signal_association(_residual(gain, seed=2)))["eta2_beyond_current"]
    assert high > low
