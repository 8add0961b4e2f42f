"""Dither demodulation: nominal current, dither amplitude and frequency from the raw current.

When a log holds only the measured solenoid current (dither included), the signals the models
need are estimated per sample:

1. **frequency** — the spectral peak of the linearly detrended current in sliding Hann
   windows (default 0.25 s, hop 1/4 window, zero-padded 4×, parabolic interpolation of the
   log power), interpolated between window centres. Windows without a clear line (peak less
   than 20 × the median power of the band, or amplitude below 3 noise σ or below 1 mA) do not
   count; their samples take the frequency of the nearest window with a strong line (≥ 6 σ).
2. **nominal current** — :func:`~clutchlab.data.derived.dither_period_mean` over exactly one
   (fractional) period at that frequency. For an unfiltered square wave (sharp edges) the
   mean of the square template over the same window is removed as well: a period that is
   not a whole number of samples holds one sample more on one side of an edge.
3. **waveform** — sine, triangle or square, from the third harmonic relative to the
   fundamental (complex demodulation at 1× and 3× the frequency): its ratio
   ``q = a3·|a1|²/a1³`` is 0 for a sine, +1/9 for a triangle, −1/3 for a square. More robust
   to noise than a peak-to-RMS ratio, since it averages over every period.
4. **amplitude** — twice the magnitude of the fundamental (complex demodulation over one
   period, then averaged over at least 2 periods and 50 ms) divided by the fundamental of
   the unit waveform (:data:`FUNDAMENTAL_RATIO`: 1, 8/π², 4/π). Linear in the amplitude, so
   an amplitude that changes along a ramp is not biased, unlike an RMS.
5. **clipping** — a PWM driver cannot drive negative current, so where the nominal current I
   is below the dither amplitude A the command is ``max(0, I + A·w)`` and the period mean is
   biased upwards; behind the current loop the measured current also lags the command, so
   the troughs decay towards 0 mA instead of being cut flat. Candidate periods have their
   troughs in the lowest third of the swing, in stretches whose troughs reach 0 mA (within
   ±5 σ) and never go clearly below it (a driver that reverses the current has no floor).
   There :func:`~clutchlab.data._dither_clip.fit_clipped` fits the measured current, by
   least squares over windows of at least 2 periods and 50 ms, with the clipped command
   through a first-order loop, ``L_τ[max(0, I(t) + A(t)·w(θ + atan 2πfτ))]``, I and A
   straight lines in each window (linear in them once the samples where the command is
   positive are fixed, so the fit alternates between that mask and the solve). The loop time
   constant τ is one per trace, estimated as the one that minimises that residual on the
   most deeply clipped stretches (0 without a loop; reported as ``loop_tau_s``). Periods
   where the fitted command goes below 0 mA are flagged in ``clipped`` and take the fitted
   nominal current; their amplitude is the fundamental of the measured current divided by
   the share of the fundamental the clipped waveform keeps (``clipped_fundamental`` of
   I/A; the loop scales every harmonic alike), or the fitted amplitude where the command is
   off more than half the time. A clipped square wave cannot be separated into I and A
   (its top is flat): its periods are flagged but keep the period mean.

The noise σ is the smaller of the spectral floor above the dither band and the robust
spread (MAD) of the residual of the fitted waveform.

The amplitude is that of the dither *in the measured current*: behind a current loop with
time constant τ it is the commanded amplitude times ``|1 / (1 + j·2πf·τ)|`` (4.6 % less at
50 Hz for τ = 1 ms); the loop time constant is only known (``loop_tau_s``) when the dither
is clipped somewhere in the trace.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..errors import DataError
from ._dither_clip import clipped_fundamental, fit_clipped
from ._dither_clip import runs as _runs
from ._dither_clip import template as _template
from .derived import didt, dither_period_mean
from .manifest import WAVEFORMS
from .trace import Trace

__all__ = [
    "FUNDAMENTAL_RATIO",
    "NO_DITHER_AMPLITUDE",
    "NO_DITHER_DIDT_HZ",
    "NO_DITHER_FREQUENCY",
    "DitherEstimate",
    "demodulate_dither",
    "demodulate_trace",
    "didt_period_samples",
    "dither_in_current",
    "no_dither_amplitude_note",
    "no_dither_frequency_note",
    "nominal_current",
    "nominal_didt",
]

#: Amplitude of the fundamental of each unit-amplitude dither waveform (Fourier series).
FUNDAMENTAL_RATIO = {"sine": 1.0, "triangle": 8.0 / math.pi**2, "square": 4.0 / math.pi}
_SNR_MIN = 20.0
_AMP_MIN_NOISE = 3.0  # a window's line must be at least this many noise σ
#: Frequency (Hz) whose period the dI/dt window counts in when there is no dither at all
#: (:func:`didt_period_samples`; an FMU's causal dI/dt at a dither frequency input of 0).
NO_DITHER_DIDT_HZ = 50.0
#: Smallest line amplitude (mA) that counts as a dither. Dithers are tens to hundreds of mA;
#: a noise-free, quantized current without dither (a simulation's export) shows its
#: quantization as a line of a tenth of the step (0.1 mA at 120 Hz for a 0.5 mA step on a
#: 220 mA/s ramp), which the noise test alone took for a dither.
_AMP_MIN_MA = 1.0
_AMP_SMOOTH_S = 0.05  # the amplitude is averaged over at least 2 periods and 50 ms
_SHARP_EDGES = 0.05  # at most this fraction of square-wave samples between -A/2 and A/2
_Q_TRIANGLE = 0.04  # Re q above: triangle
_Q_SQUARE = -0.12  # Re q below: square


@dataclass(frozen=True)
class DitherEstimate:
    """Per-sample dither estimate from the measured current.

    Parameters
    ----------
    nominal_mA : numpy.ndarray
        Nominal current (dither removed), mA.
    amplitude_mA : numpy.ndarray
        Dither amplitude (peak, zero to peak), mA; 0 where no dither is found.
    frequency_Hz : numpy.ndarray
        Dither frequency, Hz; held from the nearest window with dither where there is none
        (0 everywhere if no dither is found at all).
    waveform : str
        ``"sine"``, ``"triangle"``, ``"square"``, or ``"none"`` if no dither is found.
    present : numpy.ndarray
        Boolean, True where the dither line is detected.
    clipped : numpy.ndarray
        Boolean, True where the dither troughs are cut off at 0 mA.
    noise_mA : float
        Standard deviation of the broadband noise on the current, mA.
    loop_tau_s : float
        Time constant of the current loop (first order) estimated from the clipped periods,
        s; NaN if no period is clipped (or the waveform is square).
    """

    nominal_mA: np.ndarray
    amplitude_mA: np.ndarray
    frequency_Hz: np.ndarray
    waveform: str
    present: np.ndarray
    clipped: np.ndarray
    noise_mA: float
    loop_tau_s: float = math.nan


def _windows(n: int, length: int, hop: int) -> np.ndarray:
    if n <= length:
        return np.array([0])
    starts = np.arange(0, n - length + 1, hop)
    if starts[-1] != n - length:
        starts = np.append(starts, n - length)
    return starts


def _track(
    x: np.ndarray, fs: float, f_lo: float, f_hi: float, length: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """Window centres, peak frequency, validity and line amplitude per window; noise σ."""
    length = min(length, x.size)
    hop = max(length // 4, 1)
    nfft = 1 << math.ceil(math.log2(4 * length))
    starts = _windows(x.size, length, hop)
    window = np.hanning(length)
    tt = np.arange(length) - (length - 1) / 2.0
    freqs = np.fft.rfftfreq(nfft, 1.0 / fs)
    band = np.flatnonzero((freqs >= f_lo) & (freqs <= f_hi))
    high = np.flatnonzero(freqs >= max(f_hi, 0.25 * fs))
    if band.size < 3:
        raise DataError(f"dither band {f_lo:g}–{f_hi:g} Hz is too narrow at {fs:g} Hz")
    f_peak = np.empty(starts.size)
    valid = np.empty(starts.size, dtype=bool)
    floor_var = np.empty(starts.size)
    amp = np.empty(starts.size)
    w2, w1 = float(np.sum(window**2)), float(np.sum(window))
    for c0 in range(0, starts.size, 1024):
        idx = starts[c0 : c0 + 1024, None] + np.arange(length)
        seg = x[idx]
        seg = seg - seg.mean(axis=1, keepdims=True)
        seg = seg - (seg @ tt / np.dot(tt, tt))[:, None] * tt
        power = np.abs(np.fft.rfft(seg * window, nfft, axis=1)) ** 2
        pb = power[:, band]
        k = np.argmax(pb, axis=1)
        kk = band[k]
        rows = np.arange(kk.size)
        inner = (k > 0) & (k < band.size - 1)
        lm = np.log(power[rows, np.maximum(kk - 1, 0)] + 1e-300)
        l0 = np.log(power[rows, kk] + 1e-300)
        lp = np.log(power[rows, np.minimum(kk + 1, power.shape[1] - 1)] + 1e-300)
        denom = lm - 2.0 * l0 + lp
        delta = np.where(inner & (denom < 0), 0.5 * (lm - lp) / np.where(denom < 0, denom, -1), 0)
        sl = slice(c0, c0 + kk.size)
        f_peak[sl] = (kk + delta) * fs / nfft
        snr = pb[rows, k] / np.maximum(np.median(pb, axis=1), 1e-300)
        ref = power[:, high] if high.size >= 8 else pb
        # white noise: |X|² is exponential with mean σ²·Σw²; its 20 % quantile (0.223 × mean)
        # ignores the dither's harmonics (and their aliases) occupying up to 80 % of the bins
        floor_var[sl] = np.quantile(ref, 0.2, axis=1) / (-math.log(0.8) * w2)
        amp[sl] = 2.0 * np.sqrt(pb[rows, k]) / w1
        valid[sl] = inner & (snr >= _SNR_MIN)
    noise = float(np.sqrt(np.median(floor_var)))
    valid &= amp >= max(_AMP_MIN_NOISE * noise, _AMP_MIN_MA)
    return starts + (length - 1) / 2.0, f_peak, valid, amp, noise


def _running(x: np.ndarray, size: int, fn: str) -> np.ndarray:
    from scipy.ndimage import maximum_filter1d, minimum_filter1d

    f = minimum_filter1d if fn == "min" else maximum_filter1d
    return f(x, size=max(size, 1), mode="nearest")


def demodulate_dither(
    current_mA: ArrayLike,
    sample_rate_Hz: float,
    *,
    waveform: str = "auto",
    freq_range_Hz: tuple[float, float] | None = None,
    window_s: float = 0.25,
) -> DitherEstimate:
    """Estimate nominal current, dither amplitude and frequency from the measured current.

    Parameters
    ----------
    current_mA : array_like
        Measured solenoid current with dither, mA, uniformly sampled, finite.
    sample_rate_Hz : float
        Sample rate, Hz (at least 10 × the dither frequency).
    waveform : {"auto", "sine", "triangle", "square"}, optional
        Dither waveform; ``"auto"`` classifies it from the third harmonic.
    freq_range_Hz : (float, float), optional
        Band searched for the dither line, Hz; default 10 Hz to ``sample_rate_Hz / 5``.
    window_s : float, optional
        Length of the spectral windows, s (default 0.25 s: 2.5 periods at 10 Hz).

    Returns
    -------
    DitherEstimate
        Per-sample nominal current (mA), amplitude (mA), frequency (Hz), the waveform, and
        the masks of detected and clipped dither (see the module docstring for the method).

    Raises
    ------
    DataError
        If the current is not finite and 1-D, has fewer than 16 samples, or an argument is
        out of range.
    """
    x = np.asarray(current_mA, dtype=np.float64)
    if x.ndim != 1 or x.size < 16:
        raise DataError(f"current_mA must be 1-D with at least 16 samples, got shape {x.shape}")
    if not np.isfinite(x).all():
        i = int(np.flatnonzero(~np.isfinite(x))[0])
        raise DataError(f"current_mA has a non-finite value at row {i + 1}")
    fs = float(sample_rate_Hz)
    if not math.isfinite(fs) or fs <= 0:
        raise DataError(f"sample_rate_Hz must be positive, got {sample_rate_Hz!r}")
    if waveform != "auto" and waveform not in WAVEFORMS:
        raise DataError(f"waveform must be 'auto' or one of {', '.join(WAVEFORMS)}")
    f_lo, f_hi = freq_range_Hz if freq_range_Hz is not None else (10.0, fs / 5.0)
    if not 0 < f_lo < f_hi <= fs / 2:
        raise DataError(f"freq_range_Hz must satisfy 0 < low < high <= {fs / 2:g} Hz")
    length = max(round(window_s * fs), 16)

    centres, f_win, valid, amp_win, noise = _track(x, fs, f_lo, f_hi, length)
    n = x.size
    pos = np.arange(n, dtype=np.float64)
    if not valid.any():
        zeros = np.zeros(n)
        return DitherEstimate(
            x.copy(), zeros, zeros.copy(), "none", zeros.astype(bool), zeros.astype(bool), noise
        )
    strong = valid & (amp_win >= 2.0 * _AMP_MIN_NOISE * noise)
    anchors = strong if strong.any() else valid
    freq = np.interp(pos, centres[anchors], f_win[anchors])
    present = np.interp(pos, centres, valid.astype(np.float64)) >= 0.5
    period = fs / freq
    nominal = dither_period_mean(x, period)
    d = x - nominal

    # Complex demodulation: fundamental a1 and third harmonic a3 over one period each.
    cycles = np.cumsum(freq / fs)
    e1 = np.exp(-2j * math.pi * cycles)
    z1 = d * e1
    a1 = dither_period_mean(z1.real, period) + 1j * dither_period_mean(z1.imag, period)
    a1_smooth = dither_period_mean(a1.real, 2.0 * period) + 1j * dither_period_mean(
        a1.imag, 2.0 * period
    )
    smooth = np.maximum(2.0 * period, _AMP_SMOOTH_S * fs)  # samples
    fundamental = 2.0 * dither_period_mean(np.abs(a1), smooth)  # zero-to-peak, mA
    size = math.ceil(float(period.max())) + 1
    low = _running(x, size, "min")
    high = _running(x, size, "max")
    # Where the dither may reach the 0 mA floor: troughs in the lowest third of the swing
    # (behind a current loop the measured troughs stay above 0 when the command just clips).
    zone = present & (fundamental > 3.0 * noise) & (low < 0.35 * (high - low) + 5.0 * noise)
    for lo, hi in _runs(zone):  # the troughs must reach 0 mA somewhere, and not go below
        if not -5.0 * noise <= low[lo:hi].min() <= 5.0 * noise:
            zone[lo:hi] = False
    clear = present & ~zone

    if waveform == "auto":
        z3 = d * e1**3
        a3 = dither_period_mean(z3.real, period) + 1j * dither_period_mean(z3.imag, period)
        sel = clear & (fundamental > 5.0 * noise) & (np.abs(a1) > 0)
        if sel.sum() < 16:
            sel = present & (fundamental > 5.0 * noise) & (np.abs(a1) > 0)
        if sel.any():
            q = a3[sel] * np.abs(a1[sel]) ** 2 / a1[sel] ** 3
            q_med = float(np.median(q.real))
            waveform = (
                "triangle" if q_med > _Q_TRIANGLE else "square" if q_med < _Q_SQUARE else "sine"
            )
        else:
            waveform = "sine"
    amplitude = fundamental / FUNDAMENTAL_RATIO[waveform]
    phase = np.unwrap(np.angle(a1_smooth))
    theta = 2.0 * math.pi * cycles + phase + math.pi / 2.0
    w = _template(theta, waveform)
    if waveform == "square":
        # A sampled square wave whose period is not a whole number of samples puts one
        # sample more on one side of an edge in some periods, so its one-period mean is off
        # by up to 2A/P. With sharp edges (no samples in transition: an unfiltered square)
        # the mean of the template over the same window removes that error.
        sel = clear & (amplitude > 5.0 * noise)
        ratio = np.abs(d[sel]) / amplitude[sel]
        if ratio.size and float(np.mean(ratio < 0.5)) < _SHARP_EDGES:
            offset = dither_period_mean(w, period)
            nominal = nominal - np.where(present, amplitude, 0.0) * offset

    # The spectral floor overestimates the noise when the waveform's harmonics (and their
    # aliases) fill the spectrum (an ideal square wave); the residual of the ideal waveform
    # overestimates it when the waveform is filtered. Take the smaller (robust: MAD).
    if clear.sum() >= 16:
        resid = (x - nominal - amplitude * w)[clear]
        mad = 1.4826 * float(np.median(np.abs(resid - np.median(resid))))
        noise = min(noise, mad)

    clipped = np.zeros(n, dtype=bool)
    loop_tau = math.nan
    if zone.any() and waveform != "square":
        nominal, amp_fit, fitted, command_amp, loop_tau = fit_clipped(
            x, zone, theta, freq, fs, nominal, amplitude, smooth, waveform
        )
        clipped = fitted & (nominal < command_amp)
        # The fundamental of the measured current is that of the clipped command through
        # the loop: divided by the clipped waveform's share it is the amplitude in the
        # measured current (the plain estimate where nothing is clipped). Where the command
        # is off more than half the time (I < 0) that share is small: the fitted amplitude.
        ratio = np.where(clipped, nominal / np.where(clipped, command_amp, 1.0), 1.0)
        share = clipped_fundamental(ratio, waveform)
        amplitude = (
            2.0 * dither_period_mean(np.abs(a1) / np.maximum(share, 0.5), smooth)
        ) / FUNDAMENTAL_RATIO[waveform]
        amplitude = np.where(clipped & (share < 0.5), amp_fit, amplitude)
    elif zone.any():  # a clipped square wave has a flat top: I and A are not separable
        clipped = zone & (np.abs(low) <= 5.0 * noise)
    amplitude = np.where(present, amplitude, 0.0)
    return DitherEstimate(nominal, amplitude, freq, waveform, present, clipped, noise, loop_tau)


def didt_period_samples(trace: Trace, estimate: DitherEstimate | None = None) -> float:
    """Samples per dither period as the dI/dt window counts it (:func:`nominal_didt`).

    The ``dither_freq_Hz`` column, else the manifest value, else the demodulated frequency
    (``estimate``); without any dither, the period of 50 Hz, so that a window of a few
    periods still averages the current noise (unlike
    :func:`~clutchlab.data.derived.dither_period_samples`, which is 1 sample then).

    Parameters
    ----------
    trace : Trace
        The experiment.
    estimate : DitherEstimate, optional
        Its dither estimate, when one was made.

    Returns
    -------
    float
        Samples (fractional).
    """
    fs = trace.sample_rate_Hz
    if trace.has("dither_freq_Hz"):
        f = trace.get("dither_freq_Hz")
        f = f[np.isfinite(f) & (f > 0)]
        if f.size:
            return fs / float(np.median(f))
    meta_f = trace.meta.get("dither_freq_Hz")
    if isinstance(meta_f, int | float) and not isinstance(meta_f, bool) and meta_f > 0:
        return fs / float(meta_f)
    if estimate is not None and estimate.present.any():
        return fs / float(np.median(estimate.frequency_Hz[estimate.present]))
    return max(fs / NO_DITHER_DIDT_HZ, 1.0)


#: How the note on an experiment without a dither frequency begins (``LoadReport.notes``).
NO_DITHER_FREQUENCY = "no dither frequency"
#: How the note on a command-only experiment without a dither amplitude begins.
NO_DITHER_AMPLITUDE = "no dither amplitude"


def dither_in_current(current_mA: ArrayLike, sample_rate_Hz: float) -> float | None:
    """The dither frequency of a measured current, when it clearly carries one.

    Parameters
    ----------
    current_mA : array_like
        Measured solenoid current, mA, uniformly sampled.
    sample_rate_Hz : float
        Its sample rate, Hz.

    Returns
    -------
    float or None
        Median demodulated frequency (Hz, 3 significant digits) where
        :func:`demodulate_dither` finds a dither line; None when it finds one over less
        than a quarter of the samples, or the current cannot be demodulated (too short,
        not finite).
    """
    x = np.asarray(current_mA, dtype=np.float64)
    if x.ndim != 1 or not math.isfinite(sample_rate_Hz) or sample_rate_Hz <= 0:
        return None
    try:
        with np.errstate(all="ignore"):
            est = demodulate_dither(x, sample_rate_Hz)
    except (DataError, ValueError):  # too short or odd to demodulate: nothing to say
        return None
    freq = est.frequency_Hz[est.present & np.isfinite(est.frequency_Hz)]
    if freq.size < 0.25 * x.size:
        return None
    return float(f"{np.median(freq):.3g}")


def no_dither_frequency_note(freq_Hz: float) -> str:
    """The note on an experiment without a dither frequency whose measured current carries
    a dither at ``freq_Hz`` (Hz; :func:`dither_in_current`).

    Without a dither frequency (no ``dither_freq_Hz`` column, manifest key or channel-map
    default) every dither-period mean downstream — the physics fit's cost, the ramp rate that
    picks the quasi-static experiments, the report's primary scores — is taken over the
    period of the frequency found here (the log's ``dither_freq_found_Hz`` metadata,
    :func:`~clutchlab.data.derived.dither_period_samples`; before session 43, over single
    samples of a dithered current and pressure). The note says so and where to declare the
    frequency; it begins with :data:`NO_DITHER_FREQUENCY`.
    """
    return (
        f"{NO_DITHER_FREQUENCY} (no 'dither_freq_Hz' column, manifest key or channel-map "
        f"default), but its measured current carries a dither at about {freq_Hz:.3g} Hz: "
        "that frequency, demodulated, sets the dither-period means (the physics fit's cost, "
        "the ramp rate that picks the quasi-static experiments, the report's primary "
        f'scores); declare it to be sure: "dither_freq_Hz": {freq_Hz:.3g} in its manifest '
        f"entry, or dither_freq_Hz = {freq_Hz:.3g} under [defaults] in its channel map"
    )


def no_dither_amplitude_note(trace: Trace) -> str | None:
    """The note on a command-only experiment without a dither amplitude, or None.

    With the command current only (no measured ``current_mA`` to demodulate), no
    ``dither_amp_mA`` column or channel-map default and no manifest ``dither_amp_mA``, the
    physics model is driven with a dither of 0 mA and the ML variants cannot build their
    dither-amplitude feature; nothing said so before a fit.

    Parameters
    ----------
    trace : Trace
        One experiment, canonical signals.

    Returns
    -------
    str or None
        The note, beginning with :data:`NO_DITHER_AMPLITUDE`; None when an amplitude is
        given or can be demodulated.
    """
    if trace.has("current_mA") or trace.has("dither_amp_mA"):
        return None
    amp = trace.meta.get("dither_amp_mA")
    if isinstance(amp, int | float) and not isinstance(amp, bool):
        return None
    return (
        f"{NO_DITHER_AMPLITUDE} (no 'dither_amp_mA' column, manifest key or channel-map default) "
        "and no measured current_mA to demodulate it from: the physics model is driven "
        "without dither, and the ML variants cannot build their dither features; log it, or "
        'declare a constant ("dither_amp_mA": ... in its manifest entry, or dither_amp_mA = '
        "... under [defaults] in its channel map)"
    )


def demodulate_trace(trace: Trace, *, waveform: str | None = None) -> DitherEstimate:
    """Dither estimate of a trace's measured current.

    Parameters
    ----------
    trace : Trace
        Trace with ``current_mA`` (mA) on a uniform time base.
    waveform : str, optional
        Dither waveform; default ``trace.meta["dither_waveform"]`` if set, else ``"auto"``.

    Returns
    -------
    DitherEstimate

    Raises
    ------
    DataError
        If the trace has no ``current_mA``.
    """
    if not trace.has("current_mA"):
        raise DataError(f"trace {trace.name!r}: no current_mA to demodulate")
    wave = waveform or trace.meta.get("dither_waveform") or "auto"
    return demodulate_dither(trace.get("current_mA"), trace.sample_rate_Hz, waveform=wave)


def nominal_current(trace: Trace) -> np.ndarray:
    """Nominal (dither-free) current of a trace, mA.

    Parameters
    ----------
    trace : Trace
        Trace with ``current_cmd_mA`` or ``current_mA``.

    Returns
    -------
    numpy.ndarray
        ``current_cmd_mA`` if present, else the nominal current demodulated from
        ``current_mA``, mA.
    """
    if trace.has("current_cmd_mA"):
        return np.asarray(trace.get("current_cmd_mA"), dtype=np.float64)
    return demodulate_trace(trace).nominal_mA


def nominal_didt(trace: Trace, periods: float = 5.0) -> np.ndarray:
    """Filtered dI/dt of the nominal current, mA/s (direction of travel along a ramp).

    The nominal current (:func:`nominal_current`, already free of dither when demodulated)
    is differentiated by :func:`~clutchlab.data.derived.didt` over ``periods`` dither periods.
    On stand data (2 mA current noise, 1 kHz, 50 Hz dither, current_mA only) the default of
    5 periods (100 ms) gives about 6 mA/s RMS error and the right sign on a 27 mA/s ramp;
    1 period gives about 35 mA/s.

    Parameters
    ----------
    trace : Trace
        Trace with ``current_cmd_mA`` or ``current_mA``, uniform time base.
    periods : float, optional
        Savitzky–Golay window in dither periods (default 5); longer is smoother but rounds
        the corners of the ramp profile more.

    Returns
    -------
    numpy.ndarray
        dI/dt, mA/s.

    Raises
    ------
    DataError
        If ``periods`` is not positive or the trace has no current.
    """
    if not periods > 0:
        raise DataError(f"periods must be > 0, got {periods!r}")
    estimate = None
    if trace.has("current_cmd_mA"):
        current = np.asarray(trace.get("current_cmd_mA"), dtype=np.float64)
    else:
        estimate = demodulate_trace(trace)
        current = estimate.nominal_mA
    n = periods * didt_period_samples(trace, estimate)
    return didt(current, trace.sample_rate_Hz, n)
