"""Simulation: ROS2 vs an adaptive Radau reference, compiled vs interpreted, drives, results."""

from __future__ import annotations

import numpy as np
import pytest

from clutchlab.data import Dataset, Trace
from clutchlab.errors import DataError, ModelError, SimulationError
from clutchlab.physics import CircuitModel, SimulationSettings, simulate, simulate_inputs
from clutchlab.physics.inputs import input_matrix

MODEL = CircuitModel()
PARAMS = MODEL.default_params()


@pytest.fixture(scope="module")
def window(fast_ramp_trace):
    """0.25 s of the dithered fast ramp (220–330 mA), its inputs and a settled start state."""
    tr = fast_ramp_trace.slice_time(1.0, 1.25)
    u = input_matrix(tr, "command", SimulationSettings())
    x0, _ = simulate_inputs(
        MODEL, PARAMS, tr.time_s[:2], u[:2], "command", SimulationSettings(substeps=16)
    )
    return tr, u, x0[0]


def test_ros2_converges_to_the_radau_reference(window):
    """Same start state, same inputs: ROS2 error falls with the step, second order.

    Radau at rtol 1e-9 is the reference. At the default 4 substeps (0.25 ms) the
    sensor output is within 0.02 bar of it — below the stand's noise σ (0.025 bar).
    """
    tr, u, x0 = window
    _, y_ref = simulate_inputs(
        MODEL,
        PARAMS,
        tr.time_s,
        u,
        "command",
        SimulationSettings(method="radau", rtol=1e-9, atol=1e-10),
        x0=x0,
    )
    errors = {}
    for sub in (2, 4, 8):
        _, y = simulate_inputs(
            MODEL,
            PARAMS,
            tr.time_s,
            u,
            "command",
            SimulationSettings(substeps=sub, compile="never"),
            x0=x0,
        )
        errors[sub] = np.max(np.abs(y[:, 0] - y_ref[:, 0]))
    assert errors[4] < 0.02
    assert errors[8] < errors[4] / 2.5 < errors[2] / 2.5 / 2.5


def test_outputs_are_the_output_map_of_the_states(window):
    tr, u, x0 = window
    x, y = simulate_inputs(MODEL, PARAMS, tr.time_s, u, "command", SimulationSettings(), x0=x0)
    out = MODEL.functions("command").out
    y_ref = np.asarray(out.map(len(tr))(x.T, u.T, PARAMS.vector())).T
    assert np.max(np.abs(y - y_ref)) < 1e-9


def test_compiled_equals_interpreted(window):
    tr, u, x0 = window
    runs = [
        simulate_inputs(
            MODEL,
            PARAMS,
            tr.time_s,
            u,
            "command",
            SimulationSettings(compile=mode, chunk=100),
            x0=x0,
        )[1]
        for mode in ("always", "never")
    ]
    assert np.max(np.abs(runs[0] - runs[1])) < 1e-9


def test_measured_and_command_drive_agree_on_stand_data(stand_run):
    """The stand's measured current (noise σ 2 mA, 0.5 mA steps) drives the model like the command.

    Tolerance 0.05 bar on the dither-period mean: what the current noise and the
    1 kHz linear interpolation of a 30–70 Hz dither cost.
    """
    from clutchlab.data import dither_period_mean as period_mean

    trace = stand_run.dataset["medium_50Hz_B"]
    meas = simulate(MODEL, PARAMS, trace)
    cmd = simulate(MODEL, PARAMS, trace, SimulationSettings(drive="command"))
    assert meas.drive == "measured" and cmd.drive == "command"
    diff = period_mean(meas.pressure_bar, 20) - period_mean(cmd.pressure_bar, 20)
    assert np.sqrt(np.mean(diff**2)) < 0.05


def test_result_object_tabulates_and_plots(fast_ramp_trace):
    import matplotlib

    matplotlib.use("Agg")
    res = simulate(
        MODEL, PARAMS, fast_ramp_trace.slice_time(0, 1.0), SimulationSettings(compile="never")
    )
    df = res.to_pandas(states=True)
    assert list(df.columns[:2]) == ["time_s", "clutch_pressure_bar"]
    assert "state_p_c" in df.columns and df.attrs["units"]["state_p_c"] == "bar"
    assert df.attrs["units"]["clutch_pressure_bar"] == "bar"
    assert len(df) == len(fast_ramp_trace.slice_time(0, 1.0))
    assert res.real_time_factor > 0
    fig = res.plot(measured=fast_ramp_trace.slice_time(0, 1.0))
    assert len(fig.axes) == 2


def test_plot_refuses_a_measured_trace_off_the_simulated_grid(fast_ramp_trace):
    """The whole trace of a simulated slice failed inside matplotlib ("x and y must have same
    first dimension"); another trace of the same length was drawn against this result's
    current without a word."""
    import matplotlib

    matplotlib.use("Agg")
    part = fast_ramp_trace.slice_time(0, 1.0)
    res = simulate(MODEL, PARAMS, part, SimulationSettings(compile="never"))
    with pytest.raises(ModelError, match=r"not on the time grid .*slice_time"):
        res.plot(measured=fast_ramp_trace)
    shifted = Trace("other", dict(part.signals) | {"time_s": part.time_s + 2.0}, part.meta)
    with pytest.raises(ModelError, match=r"measured trace 'other' \(1001 samples, 2–3 s\)"):
        res.plot(measured=shifted)


def test_bad_settings_and_missing_inputs_are_clear_errors(fast_ramp_trace):
    with pytest.raises(ModelError, match="substeps"):
        SimulationSettings(substeps=0)
    with pytest.raises(DataError, match="current_mA"):
        simulate(MODEL, PARAMS, fast_ramp_trace, SimulationSettings(drive="measured"))


def test_a_parameter_set_of_another_model_is_an_error(fast_ramp_trace):
    """``simulate`` read a set of another model by position: silently 0.85 bar off for two
    effects with as many parameters, 2.84 bar for the free-threshold latch law; with other
    counts a raw CasADi error."""
    tr = fast_ramp_trace.slice_time(0, 0.2)
    lag, delay = MODEL.with_effects("sensor_lag"), MODEL.with_effects("transport_delay")
    free_latch = MODEL.with_effects("latch_free_thresholds")
    with pytest.raises(ModelError, match=r"missing .*delay_d, delay_d0\n.*extra .*slag_kappa"):
        simulate(delay, lag.default_params(), tr)
    with pytest.raises(ModelError, match=r"missing .*lthr_p_on, lthr_p_off\n.*extra .*latch_F0"):
        simulate(free_latch, PARAMS, tr)
    with pytest.raises(ModelError, match=r"missing \(the model has them\): slag_kappa, slag_tau"):
        simulate(lag, PARAMS, tr)
    with pytest.raises(ModelError, match="must be a ParameterSet"):
        simulate(MODEL, {"reg_F_c": 1.2}, tr)


def test_every_bad_simulation_setting_is_listed_at_construction():
    """``settle_s`` NaN skipped the settling silently, 1e6 s asked for 89 GiB; a float
    ``substeps`` / ``chunk`` and a negative Radau ``rtol`` failed deep inside."""
    nan = float("nan")
    with pytest.raises(ModelError) as err:
        SimulationSettings(substeps=2.5, chunk=10.5, settle_s=nan, rtol=-1.0, atol=nan)
    text = str(err.value)
    for name in ("substeps 2.5", "chunk 10.5", "settle_s nan", "rtol -1.0", "atol nan"):
        assert name in text
    for kw in (
        {"settle_s": 1e6},
        {"settle_s": -1.0},
        {"substeps": True},
        {"oil_temp_C": nan},
        {"method": "radau", "rtol": 2.0},
    ):
        with pytest.raises(ModelError, match=next(iter(kw.keys() - {"method"}))):
            SimulationSettings(**kw)
    SimulationSettings(substeps=np.int64(8), settle_s=60.0, chunk=1)  # the limits pass


def test_bad_inputs_are_named_before_anything_is_integrated(fast_ramp_trace):
    """A 1-sample trace gave a numpy broadcast error; NaN in a current or dither frequency
    and inf in the line pressure a SimulationError blaming the parameters ("the integrator
    diverged"); a non-numeric metadata dither frequency a raw ValueError."""
    from clutchlab.data import Trace

    tr = fast_ramp_trace.slice_time(0, 0.2)
    with pytest.raises(DataError, match="at least 2 samples"):
        simulate(MODEL, PARAMS, tr.slice_time(0, 0))
    cmd = np.array(tr.get("current_cmd_mA"))
    cmd[50] = np.nan
    line = np.array(tr.get("line_pressure_bar"))
    line[70:80] = np.inf
    with pytest.raises(DataError) as err:
        simulate(MODEL, PARAMS, tr.with_signals(current_cmd_mA=cmd, line_pressure_bar=line))
    text = str(err.value)
    assert "signal 'current_cmd_mA' is nan at t = 0.05 s (sample 50" in text
    assert "signal 'line_pressure_bar' is inf at t = 0.07 s (sample 70" in text
    assert "9 more" in text and "diverged" not in text
    measured = tr.with_signals(current_mA=cmd)
    with pytest.raises(DataError, match=r"'current_mA' is nan at t = 0.05 s"):
        simulate(MODEL, PARAMS, measured)
    signals = {k: v for k, v in tr.signals.items() if k != "dither_freq_Hz"}
    for value in ("abc", float("nan"), None):
        bare = Trace("bare", signals, meta={"dither_freq_Hz": value})
        with pytest.raises(DataError, match=r"metadata dither_freq_Hz = .* is not a finite"):
            simulate(MODEL, PARAMS, bare)
    # the core loop names the input column and sample, too
    u = input_matrix(tr, "command", SimulationSettings())
    u[10, 0] = np.nan
    with pytest.raises(SimulationError, match=r"input \w+ is nan at t = 0.01 s \(sample 10\)"):
        simulate_inputs(MODEL, PARAMS, tr.time_s, u, "command", SimulationSettings())
    with pytest.raises(SimulationError, match="u N × "):
        simulate_inputs(MODEL, PARAMS, tr.time_s, u[:, :3], "command", SimulationSettings())


def test_coarse_samples_keep_the_integration_step_bounded(fast_ramp_trace):
    """``substeps`` is per sample, so the ROS2 step grew with the logging interval: at
    100 Hz the default settings gave −49.5 bar (command drive), at 10 Hz −7376…+3390 bar.
    Below 1 kHz each sample interval is now split so that the step is at most 0.5 ms. The
    result is the integration, with 0.5 ms steps, of the same inputs interpolated
    linearly: the same as that of the trace resampled to 2 kHz at 1 substep (which
    data at 1 kHz and faster get unchanged), to rounding."""
    tr = fast_ramp_trace.slice_time(0.0, 4.0)
    for rate in (10.0, 100.0, 250.0):
        coarse = tr.resample(rate)
        p = simulate(MODEL, PARAMS, coarse).pressure_bar
        fine = coarse.resample(2000.0)
        p_fine = simulate(MODEL, PARAMS, fine, SimulationSettings(substeps=1)).pressure_bar
        p_ref = np.interp(coarse.time_s, fine.time_s, p_fine)
        assert -0.5 < p.min() and p.max() < 17.7 + 0.5, rate
        assert np.max(np.abs(p - p_ref)) < 1e-6, rate

    from clutchlab.physics.settings import MAX_STEP_S, steps_per_interval

    for rate, parts in ((250.0, 2), (100.0, 5), (10.0, 50)):
        assert set(steps_per_interval(tr.resample(rate).time_s, 4)) == {parts}
    # 1 kHz and faster (time stamps with rounding noise too): exactly `substeps` per sample
    t = np.arange(8001) * 1e-3 + 1234.5
    assert steps_per_interval(t, 2) is None and steps_per_interval(t, 1) is None
    assert steps_per_interval(tr.resample(5000.0).time_s, 4) is None
    # a gap in coarse data is split as finely as the rest
    parts = steps_per_interval(np.r_[np.arange(100) * 0.01, 1.5], 4)
    assert parts[0] == 5 and parts[-1] * 4 * MAX_STEP_S >= 1.5 - 0.99


def test_a_gap_in_finely_sampled_data_keeps_the_step_bounded():
    """A 1 kHz profile followed by a hold given by a few samples 0.7 s apart (an engineer's
    own current profile): the median interval is 1 ms, so the gaps were integrated in
    ``substeps`` steps of 175 ms each and the dithered hold at 500 mA read 8.98 bar
    instead of 7.26. Intervals above 1 ms are now split as on coarse data; those of
    1 ms and less keep exactly ``substeps`` steps."""
    from clutchlab.data import Trace
    from clutchlab.physics.settings import MAX_STEP_S, steps_per_interval

    def trace(t):
        n = len(t)
        return Trace(
            "gap",
            {
                "time_s": t,
                "current_cmd_mA": np.interp(t, [0.0, 0.5, 5.0], [0.0, 500.0, 500.0]),
                "dither_amp_mA": np.full(n, 150.0),
                "dither_freq_Hz": np.full(n, 50.0),
                "clutch_pressure_bar": np.zeros(n),
            },
        )

    t_gap = np.r_[np.arange(1000) * 1e-3, 1.0, 1.7, 2.4, 3.1]
    parts = steps_per_interval(t_gap, 4)
    assert np.all(parts[:-3] == 1) and np.all(parts[-3:] * 4 * MAX_STEP_S >= 0.7 - 1e-12)
    t_fine = np.arange(3101) * 1e-3
    p_gap = simulate(MODEL, PARAMS, trace(t_gap)).pressure_bar
    p_fine = simulate(MODEL, PARAMS, trace(t_fine)).pressure_bar
    assert np.max(np.abs(p_gap[-4:] - np.interp(t_gap[-4:], t_fine, p_fine))) < 0.05


def test_inputs_in_a_wrong_unit_are_refused_not_simulated():
    """A profile built in code does not pass the data layer's checks: a current written in A
    (0 → 1.1) simulated to the prime pressure throughout, a line pressure in psi or an oil
    temperature in K ran as given, without a word. They are now refused, naming the signal,
    as a file with them is."""
    from clutchlab.data import Trace

    t = np.arange(500) * 1e-3
    base = {
        "time_s": t,
        "current_cmd_mA": np.linspace(0.0, 1.1, t.size),  # A, not mA
        "clutch_pressure_bar": np.zeros(t.size),
    }
    with pytest.raises(DataError, match=r"signal 'current_cmd_mA'.*look like amperes"):
        simulate(MODEL, PARAMS, Trace("amps", base))
    ok = base | {"current_cmd_mA": np.linspace(0.0, 1100.0, t.size)}
    bad = ok | {"line_pressure_bar": np.full(t.size, 256.7), "oil_temp_C": np.full(t.size, 313.0)}
    with pytest.raises(DataError) as err:
        simulate(MODEL, PARAMS, Trace("psi", bad))
    text = str(err.value)
    assert "signal 'line_pressure_bar'" in text and "kPa or psi" in text
    assert "signal 'oil_temp_C'" in text and "kelvin" in text
    assert np.all(np.isfinite(simulate(MODEL, PARAMS, Trace("ok", ok)).pressure_bar))


def test_arguments_of_the_wrong_type_are_named_not_attribute_errors(fast_ramp_trace):
    """simulate(model, None, dataset) failed with "'Dataset' object has no attribute 'has'",
    a DataFrame or a name likewise, settings={...} with "'dict' object has no attribute
    'drive'", swapped arguments with "'Trace' object has no attribute 'default_params'"."""
    dataset = Dataset([fast_ramp_trace])
    with pytest.raises(ModelError, match=r"trace must be one Trace, not a Dataset"):
        simulate(MODEL, None, dataset)
    with pytest.raises(ModelError, match=r"not DataFrame \(Trace.from_pandas\(df, name\)"):
        simulate(MODEL, None, fast_ramp_trace.to_pandas())
    with pytest.raises(ModelError, match=r"SimulationSettings\(\*\*settings\)"):
        simulate(MODEL, None, fast_ramp_trace, {"substeps": 2})
    with pytest.raises(ModelError, match="model must be a CircuitModel, not Trace"):
        simulate(fast_ramp_trace, None, MODEL)
