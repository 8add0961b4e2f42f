"""The test bench around a circuit: supply wander, oil temperature, sensors and ADCs.

Everything here is about the *bench*, not the circuit: line and prime pressure wander,
the oil temperature of each run, and the measurement chain (sensor noise and ADC
quantization) that turns true signals into a logged experiment. The synthetic stand
and every plant of the zoo share it, so their datasets differ only by the circuit.
This module imports nothing from the fit model (``clutchlab.physics`` components or
effects): the zoo's independence rests on it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...data import LINE_PRESSURE_BAR
from ...data.validate import MIN_SAMPLES_PER_DITHER_PERIOD
from .scenarios import DITHER_SHAPES, DitherSetting, RampProfile, dither_amplitude

__all__ = [
    "TEMPERATURE_LEVELS",
    "BenchDrive",
    "BenchNoise",
    "bench_drive",
    "bench_problems",
    "experiment_meta",
    "experiment_name",
    "measured_signals",
    "quantize",
    "wander",
]

#: Oil temperature level (°C) per dither-setting index (cycled).
TEMPERATURE_LEVELS = (40.0, 55.0, 70.0)

#: Oil temperature (°C) at the start and end of a run with ``temperature="drift"``.
DRIFT_RANGE_C = (40.0, 85.0)


def wander(rng, n, dt, mean, sigma, tau_s, clip):
    """Ornstein–Uhlenbeck wander around ``mean`` with stationary std ``sigma``, clipped.

    Parameters
    ----------
    rng : numpy.random.Generator
    n : int
        Number of samples.
    dt : float
        Sample interval (s).
    mean, sigma : float
        Mean and stationary standard deviation (unit of the signal).
    tau_s : float
        Correlation time (s).
    clip : float
        Largest excursion from ``mean`` (unit of the signal).
    """
    a = np.exp(-dt / tau_s)
    e = rng.standard_normal(n) * sigma * np.sqrt(1 - a * a)
    x = np.empty(n)
    x[0] = rng.standard_normal() * sigma
    for k in range(1, n):
        x[k] = a * x[k - 1] + e[k]
    return np.clip(mean + x, mean - clip, mean + clip)


def quantize(x, lsb):
    """``x`` rounded to multiples of ``lsb`` (no rounding when ``lsb`` ≤ 0)."""
    return np.round(x / lsb) * lsb if lsb > 0 else x


@dataclass(frozen=True)
class BenchNoise:
    """Measurement chain of the bench: sensor noise (standard deviations) and ADC steps."""

    pressure_noise_bar: float = 0.025
    current_noise_mA: float = 2.0
    pressure_lsb_bar: float = 0.01
    current_lsb_mA: float = 0.5

    def as_dict(self) -> dict[str, float]:
        """JSON-ready form (the keys the stand's truth file uses)."""
        return {
            "pressure_bar": self.pressure_noise_bar,
            "current_mA": self.current_noise_mA,
            "pressure_lsb_bar": self.pressure_lsb_bar,
            "current_lsb_mA": self.current_lsb_mA,
        }


@dataclass(frozen=True)
class BenchDrive:
    """True inputs of one experiment at the logging rate.

    Attributes
    ----------
    time_s : ndarray
        Sample times (s).
    current_nom_mA, dither_amp_mA : ndarray
        Nominal current and dither amplitude (mA).
    dither_freq_Hz : float
        Dither frequency (Hz).
    phase0 : float
        Dither phase at t = 0 (cycles).
    line_bar, prime_bar : ndarray
        True line and prime pressure (bar).
    oil_temp_C : ndarray
        True oil temperature (°C).
    """

    time_s: np.ndarray
    current_nom_mA: np.ndarray
    dither_amp_mA: np.ndarray
    dither_freq_Hz: float
    phase0: float
    line_bar: np.ndarray
    prime_bar: np.ndarray
    oil_temp_C: np.ndarray


def bench_drive(
    ramp: RampProfile,
    setting: DitherSetting,
    index: int,
    rng: np.random.Generator,
    sample_rate_Hz: float,
    temperature: str = "levels",
) -> BenchDrive:
    """Draw the bench inputs of one experiment (ramp × dither setting).

    Parameters
    ----------
    ramp, setting : RampProfile, DitherSetting
    index : int
        Index of the dither setting (selects the oil temperature level).
    rng : numpy.random.Generator
        Random stream of the run (line, prime, temperature wander, dither phase).
    sample_rate_Hz : float
        Logging rate (Hz).
    temperature : {"levels", "drift"}
        ``"levels"``: 40 / 55 / 70 °C by setting with ±0.5 °C wander. ``"drift"``: the
        oil warms from 40 to 85 °C over every run (plus the same wander).
    """
    dt = 1.0 / sample_rate_Hz
    t = np.arange(0.0, ramp.duration_s + 0.5 * dt, dt)
    n = len(t)
    i_nom = ramp.current(t)
    line = wander(rng, n, dt, LINE_PRESSURE_BAR, 0.12, 3.0, 0.3)
    prime = wander(rng, n, dt, 0.5, 0.04, 2.0, 0.1)
    if temperature == "levels":
        base = TEMPERATURE_LEVELS[index % len(TEMPERATURE_LEVELS)]
    elif temperature == "drift":
        lo, hi = DRIFT_RANGE_C
        base = lo + (hi - lo) * t / t[-1]
    else:
        raise ValueError(f"temperature must be 'levels' or 'drift', not {temperature!r}")
    temp = base + wander(rng, n, dt, 0.0, 0.5, 20.0, 1.5)
    return BenchDrive(
        time_s=t,
        current_nom_mA=i_nom,
        dither_amp_mA=dither_amplitude(setting.shape, i_nom),
        dither_freq_Hz=float(setting.freq_Hz),
        phase0=float(rng.uniform()),
        line_bar=line,
        prime_bar=prime,
        oil_temp_C=temp,
    )


def measured_signals(
    rng: np.random.Generator,
    drive: BenchDrive,
    current_mA: np.ndarray,
    pressure_bar: np.ndarray,
    noise: BenchNoise,
) -> dict[str, np.ndarray]:
    """The logged signals of one experiment: true signals through the bench's sensors.

    Parameters
    ----------
    rng : numpy.random.Generator
        Random stream of the run (sensor noise).
    drive : BenchDrive
        The experiment's true inputs.
    current_mA : ndarray
        True coil current (mA), dither included.
    pressure_bar : ndarray
        Clutch pressure at the transducer's output (bar), before noise and ADC.
    noise : BenchNoise
        Sensor noise and ADC steps.

    Returns
    -------
    dict of str to ndarray
        Canonical signals (DESIGN §3), quantized.
    """
    n = len(drive.time_s)
    p_meas = pressure_bar + rng.standard_normal(n) * noise.pressure_noise_bar
    i_meas = current_mA + rng.standard_normal(n) * noise.current_noise_mA
    return {
        "time_s": drive.time_s,
        "current_mA": quantize(i_meas, noise.current_lsb_mA),
        "current_cmd_mA": drive.current_nom_mA,
        "dither_amp_mA": drive.dither_amp_mA,
        "dither_freq_Hz": np.full(n, drive.dither_freq_Hz),
        "clutch_pressure_bar": quantize(p_meas, noise.pressure_lsb_bar),
        "line_pressure_bar": quantize(
            drive.line_bar + rng.standard_normal(n) * 0.01, noise.pressure_lsb_bar
        ),
        "prime_pressure_bar": quantize(
            drive.prime_bar + rng.standard_normal(n) * 0.005, noise.pressure_lsb_bar / 2
        ),
        "oil_temp_C": quantize(drive.oil_temp_C + rng.standard_normal(n) * 0.1, 0.1),
    }


def experiment_name(ramp: RampProfile, setting: DitherSetting) -> str:
    """Name (and file stem) of one experiment, e.g. ``fast_50Hz_B``."""
    return f"{ramp.label}_{setting.tag}"


def experiment_meta(ramp: RampProfile, setting: DitherSetting) -> dict:
    """Manifest metadata of one experiment (ramp label and dither setting)."""
    return {
        "ramp": ramp.label,
        "dither_freq_Hz": setting.freq_Hz,
        "dither_shape": setting.shape,
        "dither_waveform": setting.waveform,
    }


def _finite(v) -> bool:
    """A finite int or float, not a bool. (``physics.settings.is_finite_real`` says the same,
    but the zoo imports nothing of the fit model's modules: its independence rests on it.)"""
    return not isinstance(v, bool) and isinstance(v, int | float) and math.isfinite(v)


def bench_problems(
    settings,
    ramps,
    seed,
    sample_rate_Hz,
    substeps,
    noise: BenchNoise,
    waveforms: tuple[str, ...] = ("sine", "triangle", "square"),
) -> list[str]:
    """What is wrong with a run of the bench (empty list: nothing), every problem at once.

    Parameters
    ----------
    settings : tuple of DitherSetting
        Dither settings: at least one; frequency > 0 Hz, a known shape, one of ``waveforms``.
    ramps : tuple of RampProfile
        Ramps: at least one; ``ramp_s`` > 0 s, ``hold_s`` ≥ 0 s, 0 < ``peak_mA`` ≤ 1100 mA.
    seed : int
        Non-negative integer.
    sample_rate_Hz : float
        Logging rate (Hz): at least 10 × the highest dither frequency, so that the dataset
        passes :func:`clutchlab.data.validate_trace`.
    substeps : int
        Integration steps per sample, ≥ 1.
    noise : BenchNoise
        Standard deviations and ADC steps, each finite and ≥ 0 (bar, mA).
    waveforms : tuple of str
        Dither waveforms the circuit can make.
    """
    out: list[str] = []
    settings, ramps = tuple(settings), tuple(ramps)
    if not settings:
        out.append("settings: at least one dither setting is needed")
    if not ramps:
        out.append("ramps: at least one ramp is needed")
    for s in settings:
        if not isinstance(s, DitherSetting):
            out.append(f"settings: {s!r} is not a DitherSetting")
            continue
        if not (_finite(s.freq_Hz) and s.freq_Hz > 0):
            out.append(f"settings: dither frequency {s.freq_Hz!r} Hz must be > 0")
        if not isinstance(s.shape, str) or s.shape not in DITHER_SHAPES:
            out.append(
                f"settings: unknown dither shape {s.shape!r}; known: {sorted(DITHER_SHAPES)}"
            )
        if s.waveform not in waveforms:
            out.append(f"settings: dither waveform {s.waveform!r} is not one of {waveforms}")
    for r in ramps:
        if not isinstance(r, RampProfile):
            out.append(f"ramps: {r!r} is not a RampProfile")
            continue
        if not isinstance(r.label, str) or not r.label.strip():
            out.append(f"ramps: label {r.label!r} must be a non-empty string")
        if not (_finite(r.ramp_s) and r.ramp_s > 0 and _finite(r.hold_s) and r.hold_s >= 0):
            out.append(f"ramps: {r.label!r} needs ramp_s > 0 s and hold_s ≥ 0 s")
        if not (_finite(r.peak_mA) and 0 < r.peak_mA <= 1100):
            out.append(f"ramps: {r.label!r} peak_mA {r.peak_mA!r} not in (0, 1100] mA")
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        out.append(f"seed must be a non-negative integer, not {seed!r}")
    if isinstance(substeps, bool) or not isinstance(substeps, int | np.integer) or substeps < 1:
        out.append(f"substeps must be an integer ≥ 1, not {substeps!r}")
    if not (_finite(sample_rate_Hz) and sample_rate_Hz > 0):
        out.append(f"sample_rate_Hz must be a finite number > 0, not {sample_rate_Hz!r}")
    else:
        freqs = [s.freq_Hz for s in settings if isinstance(s, DitherSetting) and _finite(s.freq_Hz)]
        need = MIN_SAMPLES_PER_DITHER_PERIOD * max(freqs, default=0.0)
        if sample_rate_Hz < need:
            out.append(
                f"sample_rate_Hz {sample_rate_Hz:g} Hz does not resolve a {max(freqs):g} Hz "
                f"dither (at least {need:g} Hz: {MIN_SAMPLES_PER_DITHER_PERIOD:g} samples per "
                "period, or the dataset would fail its own check)"
            )
    for key, value in noise.as_dict().items():
        if not (_finite(value) and value >= 0):
            out.append(f"noise {key} must be a finite number ≥ 0, not {value!r}")
    return out
