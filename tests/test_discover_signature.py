"""Signatures that see through a poor base fit (issue 17): what a flexible map of the
current and its direction explains is removed before a signal that moves independently
of the ramp is measured."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from clutchlab.physics.stand.scenarios import dither_amplitude
from clutchlab.validation.discover import loop
from clutchlab.validation.discover.diagnostics import (
    RAMP_BOUND_R2,
    SIGNATURE_ETA2,
    current_map_residual,
    diagnose,
    ramp_bound,
    signal_association,
)
from clutchlab.validation.discover.partial import (
    PARTIAL_Z,
    current_determined_share,
    partial_hit,
    regulated_mask,
    regulated_partial,
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


def _per_rate(coupling: float, seed: int = 0, oil_drift: bool = False) -> ResidualSet:
    """What the zoo's fits leave (quadratic_play, measured): fast and slow triangle ramps
    whose misfit differs with the rate (a band ±0.4 bar wide on the fast ramps, ±0.05 on the
    slow ones), a latched plateau above 800 mA where the residual is the latch windows'
    (±0.5 bar steps), white noise, and ``coupling`` × the line-pressure wander in the
    regulated region only. With ``oil_drift`` the oil warms from 40 to 85 °C through every
    run and the residual follows that warming (it is the ramp's, as on the zoo)."""
    rng = np.random.default_rng(seed)
    rs, sig, slices, times = [], {k: [] for k in SIGNALS}, [], []
    pos = 0
    for k in range(6):
        n = 800 if k % 2 == 0 else 8000  # fast / slow
        t = np.arange(n) * 0.01
        half = n // 2
        cur = np.where(
            np.arange(n) < half, t / t[half] * 1000.0, (t[-1] - t) / (t[-1] - t[half]) * 1000.0
        )
        didt = np.gradient(cur, t)
        sign = np.sign(didt)
        wander = np.zeros(n)
        a = np.exp(-0.01 / 3.0)
        for j in range(1, n):
            wander[j] = a * wander[j - 1] + np.sqrt(1 - a * a) * 0.11 * rng.standard_normal()
        line = 17.7 + wander
        latched = cur > 800.0
        pressure = np.where(latched, line, 12.0 * cur / 1000.0)
        band = 0.4 if n == 800 else 0.05
        misfit = band * sign * np.sin(np.pi * cur / 1000.0) + 0.1 * (cur / 1000.0) ** 2
        junk = np.repeat(rng.choice([-0.5, 0.5], size=n // 50 + 1), 50)[:n]
        oil = 40.0 + 45.0 * t / t[-1] if oil_drift else np.full(n, 40.0)
        r = misfit - coupling * wander * ~latched + 0.02 * rng.standard_normal(n)
        if oil_drift:
            r = r + 0.004 * (oil - 40.0)
        rs.append(np.where(latched, junk, r))
        values = {
            "current_mA": cur,
            "didt_mA_s": didt,
            "didt_sign": sign,
            "pressure_bar": pressure,
            "dpdt_bar_s": np.gradient(pressure, t),
            "line_pressure_bar": line,
            "oil_temp_C": oil,
            "dither_amp_mA": np.full(n, 100.0),
            "dither_freq_Hz": np.full(n, 50.0),
        }
        for name in SIGNALS:
            sig[name].append(values[name])
        slices.append((pos, pos + n))
        times.append(t)
        pos += n
    return ResidualSet(
        r=np.concatenate(rs),
        experiments=[f"e{k}" for k in range(6)],
        slices=slices,
        signals={k: np.concatenate(v) for k, v in sig.items()},
        time_s=np.concatenate(times),
        row_dt_s=0.01,
        n_period=1.0,
        keep=np.ones(pos, dtype=bool),
    )


def test_a_coupling_under_a_misfit_that_differs_with_the_rate_is_seen_in_the_regulated_region():
    res = _per_rate(coupling=0.4)
    line = _line(signal_association(res))
    # the pooled map cannot hold a misfit that differs with the rate: the share is lost
    assert max(line["eta2"], line["eta2_beyond_current"]) < SIGNATURE_ETA2
    partial = line["partial_regulated"]
    assert partial["rho"] < -0.2 and partial["z"] <= -PARTIAL_Z
    assert partial["beta"] == pytest.approx(-0.4, abs=0.1)
    diag = diagnose(res)
    assert "line_pressure_bar" in diag.signature
    assert "in the regulated region" in diag.summary()


@pytest.mark.parametrize("seed", [0, 1, 2, 3])
def test_no_partial_correlation_without_a_coupling(seed):
    res = _per_rate(coupling=0.0, seed=seed)
    partial = _line(signal_association(res))["partial_regulated"]
    assert not partial_hit(partial)
    assert abs(partial["z"]) < PARTIAL_Z
    assert "line_pressure_bar" not in diagnose(res).signature


def test_a_warming_that_moves_with_the_ramp_is_removed_with_each_experiments_map():
    """The oil warms through every run: its trend within each current bin is the ramp's,
    so the map removes it with the misfit and the statistic names nothing (session 11's
    aliasing stays: no statistic on these data can separate it)."""
    res = _per_rate(coupling=0.0, oil_drift=True)
    oil = next(a for a in signal_association(res) if a["signal"] == "oil_temp_C")
    assert not partial_hit(oil["partial_regulated"])


def test_no_partial_correlation_without_regulated_samples():
    res = _per_rate(coupling=0.4)
    res.signals["pressure_bar"] = res.signals["line_pressure_bar"].copy()  # all latched
    assert regulated_partial(res, "line_pressure_bar") is None


def test_samples_where_the_model_has_latched_and_the_data_not_are_left_out():
    """A base fit that latches early predicts line pressure where the data are still
    regulated: those few samples' residual (several bar) is the latch window's, not the
    coupling's, and would drown it."""
    res = _per_rate(coupling=0.4)
    clean = regulated_partial(res, "line_pressure_bar")
    early = (res.signals["current_mA"] > 780.0) & (res.signals["current_mA"] <= 800.0)
    # the model has latched 20 mA early: it predicts line pressure there
    gap = res.signals["line_pressure_bar"] - res.signals["pressure_bar"]
    res.r = np.where(early, res.r + gap, res.r)
    assert early.any()
    seen = regulated_partial(res, "line_pressure_bar")
    assert seen["n"] == clean["n"] - int(early.sum())
    assert seen["rho"] == pytest.approx(clean["rho"], abs=0.05)
    assert partial_hit(seen)


def _dither_faded_in(res: ResidualSet) -> ResidualSet:
    """The dither faded in with the current below 70 mA, inside the lowest current cell (the zoo
    stands fade it in below 100 mA), and a misfit with the same kink: a function of the current
    that a cell's linear trend leaves (without the test for it, z ≈ +5 here)."""
    cur = res.signals["current_mA"]
    res.signals["dither_amp_mA"] = np.minimum(cur, 70.0) * 100.0 / 70.0
    res.r = res.r + 0.1 * np.minimum(cur, 70.0) / 70.0
    return res


def test_a_signal_the_current_determines_gets_no_partial_correlation():
    """Session 29: saturating_lugre seed 0 named dither_amp_mA (z +7) on a null dataset only
    because the stand fades the dither in with the current."""
    res = _dither_faded_in(_per_rate(coupling=0.0))
    assert regulated_partial(res, "dither_amp_mA") is None
    assert "dither_amp_mA" not in diagnose(res).signature


def test_a_wandering_signal_is_not_taken_for_a_function_of_the_current():
    res = _dither_faded_in(_per_rate(coupling=0.4))
    cur, sign = res.signals["current_mA"], np.sign(res.signals["didt_sign"]).astype(int)
    assert current_determined_share(res.signals["line_pressure_bar"], cur, sign) < 0.5
    assert partial_hit(regulated_partial(res, "line_pressure_bar"))


def _oil_with_the_ramp(levels: bool = False, seed: int = 0) -> ResidualSet:
    """The oil warms from 40 to 85 °C through every run, with a wander of its own (±5 °C,
    ~2 s), and the residual follows it; with ``levels`` the oil instead sits at 40 / 55 /
    70 °C by experiment (the stand's default protocol) and the residual does not follow it."""
    res = _per_rate(coupling=0.0, seed=seed, oil_drift=not levels)
    rng = np.random.default_rng(seed + 100)
    for k, (a, b) in enumerate(res.slices):
        if levels:
            res.signals["oil_temp_C"][a:b] = (40.0, 55.0, 70.0)[k % 3]
            continue
        w = np.zeros(b - a)
        c = np.exp(-0.01 / 2.0)
        for j in range(1, b - a):
            w[j] = c * w[j - 1] + np.sqrt(1 - c * c) * 5.0 * rng.standard_normal()
        res.signals["oil_temp_C"][a:b] += w
    return res


@pytest.mark.parametrize("seed", [0, 1])
def test_an_oil_that_warms_through_every_run_is_reported_as_moving_with_the_ramp(seed):
    """Issue 17: discovery said the residual "follows none of the examined signals" on a
    circuit whose oil warmed through every run. The map of the current removes such a signal
    with the misfit, so no statistic names it; the diagnostics now say which signal it is."""
    res = _oil_with_the_ramp(seed=seed)
    bound = ramp_bound(res)
    assert list(bound) == ["oil_temp_C"]
    assert RAMP_BOUND_R2 <= bound["oil_temp_C"] < 0.99
    diag = diagnose(res)
    assert diag.ramp_bound == bound
    assert "moves with the ramp in every run" in diag.summary()
    assert "oil_temp_C (" in diag.ramp_note()


def test_signals_that_do_not_move_with_the_ramp_or_that_the_current_sets_are_not_reported():
    """Oil at a level per experiment, line pressure wandering on its own, and a dither
    amplitude scheduled on the current (the stand's shape A, faded in over the first 100 mA:
    a function of the current, its own map) are not "moving with the ramp"."""
    res = _oil_with_the_ramp(levels=True)
    cur = res.signals["current_mA"]
    res.signals["dither_amp_mA"] = dither_amplitude("A", cur)
    reg = regulated_mask(res)
    sign = np.sign(res.signals["didt_sign"][reg]).astype(int)
    assert current_determined_share(res.signals["dither_amp_mA"][reg], cur[reg], sign) >= 0.99
    assert current_determined_share(res.signals["line_pressure_bar"][reg], cur[reg], sign) < 0.5
    assert ramp_bound(res) == {}
    diag = diagnose(res)
    assert diag.ramp_bound == {} and diag.ramp_note() == ""
    assert "with the ramp" not in diag.summary()


def test_a_residual_left_unexplained_names_the_signal_it_cannot_be_told_from():
    """The discovery's summary carries the note when the final residual is not white."""
    res = _oil_with_the_ramp()
    diag = diagnose(res)
    assert not diag.whiteness["white"]
    last = SimpleNamespace(
        effect=None, decision="no significant effect", candidates=[], time_limited=False
    )
    text = loop._summary([last], False, diag, 2)
    assert text.startswith("no missing effect found; stopped: no significant effect")
    assert "oil_temp_C (" in text and "moves with the ramp in every run" in text
    diag.whiteness["white"] = True  # nothing left to explain: no note
    assert "with the ramp" not in loop._summary([last], False, diag, 2)


def test_the_note_reads_for_one_signal_and_for_several():
    from clutchlab.validation.discover import Diagnostics

    one = Diagnostics(0.1, 10, 5.0, 2.0, ramp_bound={"oil_temp_C": 0.886})
    assert one.ramp_note().startswith("oil_temp_C (89%) moves with the ramp in every run")
    assert "its effect" in one.ramp_note() and "it differs" in one.ramp_note()
    two = Diagnostics(0.1, 10, 5.0, 2.0, ramp_bound={"oil_temp_C": 0.9, "line_pressure_bar": 0.6})
    note = two.ramp_note()
    assert note.startswith("oil_temp_C (90%), line_pressure_bar (60%) move with the ramp")
    assert "their effect" in note and "they differ" in note
    assert Diagnostics(0.1, 10, 5.0, 2.0).ramp_note() == ""
