"""Dither clipped at 0 mA behind a current loop: a censored local fit (private helper).

A PWM driver cannot drive negative current, so where the nominal current I is below the dither
amplitude A the command is ``max(0, I + A·w(θ))``; the measured current is that command
through the current loop, modelled as a first-order lag of time constant τ (estimated here
from the data; 0 if there is no loop). In every window of at least two dither periods and
50 ms the measured current is fitted, by least squares, with ``L_τ[max(0, I + A·w)]``, I and
A straight lines in the window: for a fixed set of samples where the command is positive (the
mask) the model is linear in the four coefficients, so the fit alternates between the mask and
a 4 × 4 solve per sample. The lag is computed on a grid 4× finer than the samples (the
command has corners where it leaves 0 mA) and is exact for an input linear on that grid.
"""

from __future__ import annotations

import math

import numpy as np

from .derived import dither_period_mean

_UPSAMPLE = 4  # fine-grid factor of the lag filter
_ITERS = 4  # mask ↔ solve iterations
_BLOCK = 8192  # samples fitted at a time
_SPAN_S = 0.05  # each local fit spans at least 2 periods and 50 ms
_TAU_CHUNK = 2000  # samples per chunk used to estimate τ
_TAU_SAMPLES = 4000  # at most this many samples (in chunks) to estimate τ
_WT_MAX = math.sqrt(3.0)  # search 2πf·τ in [0, √3]: loop gain down to 1/2 at the dither


def template(theta: np.ndarray, waveform: str) -> np.ndarray:
    """Unit dither waveform at phase ``theta`` (rad): sine, triangle or square."""
    s = np.sin(theta)
    if waveform == "triangle":
        return (2.0 / math.pi) * np.arcsin(np.clip(s, -1.0, 1.0))
    if waveform == "square":
        return np.sign(s)
    return s


def clipped_fundamental(ratio: np.ndarray, waveform: str) -> np.ndarray:
    """Fundamental of ``max(0, r + w)`` relative to that of ``w`` (unit waveform, r = I/A).

    1 for r ≥ 1 (no clipping), 0 for r ≤ −1 (always off). A current loop (linear) scales
    every harmonic of the clipped command by its gain, so the fundamental of the measured
    current over this factor is the amplitude the dither would have without the floor.
    """
    r = np.clip(np.asarray(ratio, dtype=np.float64), -1.0, 1.0)
    if waveform == "sine":  # closed form, α = arcsin r: (r·cos α + π/2 + α) / π
        alpha = np.arcsin(r)
        return (r * np.cos(alpha) + math.pi / 2.0 + alpha) / math.pi
    theta = (np.arange(2048) + 0.5) * (2.0 * math.pi / 2048)
    w = template(theta, waveform)
    s = np.sin(theta)
    grid = np.linspace(-1.0, 1.0, 401)
    table = np.maximum(grid[:, None] + w, 0.0) @ s / float(w @ s)
    return np.interp(r, grid, table)


def _box_means(rows: np.ndarray, width: int) -> np.ndarray:
    """Mean of each row of ``rows`` (m × n) over ``width`` samples centred on each sample.

    Near the ends the window is shifted to stay inside the data (as in
    :func:`~clutchlab.data.derived.dither_period_mean`, here with a whole number of samples).
    """
    m, n = rows.shape
    width = int(min(max(width, 1), n))
    cum = np.zeros((m, n + 1))
    np.cumsum(rows, axis=1, out=cum[:, 1:])
    sums = cum[:, width:] - cum[:, : n - width + 1]  # windows starting at 0 … n − width
    half = width // 2
    out = np.empty((m, n))
    out[:, :half] = sums[:, :1]
    out[:, half : half + sums.shape[1]] = sums
    out[:, half + sums.shape[1] :] = sums[:, -1:]
    return out / width


def _lag(u: np.ndarray, tau: float, up: int) -> np.ndarray:
    """First-order lag (time constant ``tau`` samples) of each row of ``u`` (grid 1/``up``).

    Exact for an input linear between grid points; starts in steady state.
    """
    from scipy.signal import lfilter

    if tau <= 1e-6:
        return u
    a = math.exp(-1.0 / (up * tau))
    c = tau * up * (1.0 - a)
    b = np.array([1.0 - c, c - a])
    zi = (1.0 - b[0]) * u[:, :1]  # steady state at u[0]: y[0] = b[0]·u[0] + z = u[0]
    return lfilter(b, np.array([1.0, -a]), u, axis=1, zi=zi)[0]


def _solve_spd(g: list[list[np.ndarray]], rhs: list[np.ndarray]) -> list[np.ndarray]:
    """Solve the symmetric positive definite systems ``g · p = rhs`` entry by entry.

    ``g[i][k]`` and ``rhs[i]`` are arrays (one system per element); Cholesky, no pivoting.
    """
    m = len(rhs)
    low = [[np.zeros(0)] * m for _ in range(m)]
    for j in range(m):
        d = g[j][j] - sum((low[j][q] ** 2 for q in range(j)), np.zeros_like(rhs[0]))
        low[j][j] = np.sqrt(np.maximum(d, 1e-300))
        for i in range(j + 1, m):
            acc = g[i][j] - sum((low[i][q] * low[j][q] for q in range(j)), np.zeros_like(d))
            low[i][j] = acc / low[j][j]
    y = []
    for i in range(m):
        y.append(
            (rhs[i] - sum((low[i][q] * y[q] for q in range(i)), np.zeros_like(rhs[0]))) / low[i][i]
        )
    p = [np.zeros(0)] * m
    for i in reversed(range(m)):
        acc = y[i] - sum((low[q][i] * p[q] for q in range(i + 1, m)), np.zeros_like(rhs[0]))
        p[i] = acc / low[i][i]
    return p


def _refine(v: np.ndarray, up: int) -> np.ndarray:
    """Linear interpolation of ``v`` (per sample) onto the grid of 1/``up`` samples."""
    frac = np.arange(up) / up
    fine = (v[:-1, None] + np.diff(v)[:, None] * frac).ravel()
    return np.append(fine, v[-1])


def _fit(
    x: np.ndarray,
    theta: np.ndarray,
    span: int,
    i0: np.ndarray,
    a0: np.ndarray,
    tau: float,
    waveform: str,
    iters: int = _ITERS,
    up: int = _UPSAMPLE,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Local fit of ``x ≈ L_τ[max(0, I(t) + A(t)·w(theta))]`` over windows of ``span`` samples.

    I and A are straight lines in each window (a ramp of the nominal current or amplitude
    would otherwise leak into the fit through the odd part of the waveform). Returns I and A
    at each window's centre, the residual, and where the fit was solvable.
    """
    n = x.size
    t = np.arange(n, dtype=np.float64) - 0.5 * (n - 1)  # centred: well-conditioned moments
    w = template(_refine(theta, up), waveform)
    t_fine = _refine(t, up)
    i_est, a_est = i0.copy(), a0.copy()
    ok = np.zeros(n, dtype=bool)
    model = np.zeros(n)
    pairs = [(i, k) for i in range(4) for k in range(i, 4)]
    u = np.empty((4, w.size))
    prods = np.empty((len(pairs) + 4, n))
    for _ in range(iters):
        u[0] = _refine(i_est, up) + _refine(a_est, up) * w > 0
        np.multiply(u[0], t_fine, out=u[1])
        np.multiply(u[0], w, out=u[2])
        np.multiply(u[2], t_fine, out=u[3])
        # Columns L[mask], L[mask·t], L[mask·w], L[mask·w·t] (the lag is linear, so the
        # trend relative to a window's centre k is L[mask·t] − k·L[mask]).
        cols = _lag(u, tau, up)[:, ::up]
        for j, (i, k) in enumerate(pairs):
            np.multiply(cols[i], cols[k], out=prods[j])
        np.multiply(cols, x, out=prods[len(pairs) :])
        mom = _box_means(prods, span)
        g0 = [[np.zeros(0)] * 4 for _ in range(4)]
        for j, (i, k) in enumerate(pairs):
            g0[i][k] = g0[k][i] = mom[j]
        rhs = list(mom[len(pairs) :])
        # Change of basis to the trend centred on each window: column t·r → (t − k)·r.
        g = [row[:] for row in g0]
        for b, bt in ((0, 1), (2, 3)):
            for c, ct in ((0, 1), (2, 3)):
                g[b][ct] = g0[b][ct] - t * g0[b][c]
                g[bt][c] = g0[bt][c] - t * g0[b][c]
                g[bt][ct] = g0[bt][ct] - t * (g0[b][ct] + g0[bt][c]) + t * t * g0[b][c]
            rhs[bt] = rhs[bt] - t * rhs[b]
        det2 = g[0][0] * g[2][2] - g[0][2] ** 2
        ok = det2 > 1e-3 * np.maximum(g[0][0] * g[2][2], 1e-12)
        for i in range(4):  # unsolvable windows: identity (their result is not used)
            for k in range(4):
                g[i][k] = np.where(ok, g[i][k], float(i == k))
        p = _solve_spd(g, rhs)
        i_est = np.where(ok, p[0], i_est)
        a_est = np.where(ok, np.maximum(p[2], 0.0), a_est)
        model = i_est * cols[0] + a_est * cols[2]
    return i_est, a_est, x - model, ok


def _argmin_1d(fun, grid: np.ndarray, tol: float = 0.01, max_evals: int = 8) -> float:
    """Minimum of a smooth 1-D function: the best grid point, then parabolic steps.

    Successive parabolic interpolation in a bracket ``a < b < c`` with ``f(b) ≤ f(a), f(c)``
    (a minimum at an end of the grid is bracketed by halving towards it).
    """
    vals = [fun(float(g)) for g in grid]
    k = int(np.argmin(vals))
    if k == 0 or k == grid.size - 1:  # at an end: halve the interval towards it
        end, other, f_end = float(grid[k]), float(grid[k - 1 if k else 1]), vals[k]
        for _ in range(max_evals):
            mid = 0.5 * (end + other)
            f_mid = fun(mid)
            if f_mid < f_end:
                a, b, c, fa, fb, fc = (end, mid, other, f_end, f_mid, math.inf)
                break
            other = mid
            if abs(other - end) < 4.0 * tol:  # flat or rising away from the end: stop
                return end
        else:
            return end
        if k:  # keep a < b < c
            a, c, fa, fc = c, a, fc, fa
    else:
        a, b, c = (float(v) for v in grid[k - 1 : k + 2])
        fa, fb, fc = vals[k - 1 : k + 2]
    for _ in range(max_evals):
        if c - a < tol:
            break
        num = (b - a) ** 2 * (fb - fc) - (b - c) ** 2 * (fb - fa)
        den = (b - a) * (fb - fc) - (b - c) * (fb - fa)  # < 0 for a convex bracket
        v = b - 0.5 * num / den if den < 0 and math.isfinite(fa + fc) else math.nan
        if not a < v < c:  # no usable parabola: bisect the larger side
            v = 0.5 * (a + b) if b - a > c - b else 0.5 * (b + c)
        elif abs(v - b) < 0.5 * tol:  # the parabola's vertex has settled
            return v
        fv = fun(v)
        if fv < fb:
            a, b, c, fa, fb, fc = (a, v, b, fa, fv, fb) if v < b else (b, v, c, fb, fv, fc)
        elif v < b:
            a, fa = v, fv
        else:
            c, fc = v, fv
    return b


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of every run of True in ``mask``."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(np.int8), [0]])))
    return list(zip(edges[::2].tolist(), edges[1::2].tolist(), strict=True))


def fit_clipped(
    x: np.ndarray,
    zone: np.ndarray,
    theta: np.ndarray,
    freq: np.ndarray,
    fs: float,
    nominal: np.ndarray,
    amplitude: np.ndarray,
    smooth: np.ndarray,
    waveform: str,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float]:
    """Censored fit in ``zone`` (samples where the dither may reach 0 mA).

    Parameters
    ----------
    x : numpy.ndarray
        Measured current, mA.
    zone : numpy.ndarray
        Boolean, samples to fit.
    theta : numpy.ndarray
        Phase of the fundamental of the measured dither (template argument), rad.
    freq : numpy.ndarray
        Dither frequency, Hz.
    fs : float
        Sample rate, Hz.
    nominal, amplitude : numpy.ndarray
        Plain estimates (period mean, fundamental-based amplitude in the measured current), mA;
        the starting point of the fit, kept outside ``zone``.
    smooth : numpy.ndarray
        Window over which the amplitude is averaged, samples.
    waveform : str
        ``"sine"`` or ``"triangle"`` (a clipped square wave has no separable I and A).

    Returns
    -------
    nominal, amplitude, fitted, command_amplitude, tau
        Nominal current and amplitude in the measured current (the command amplitude times
        the loop gain at the dither frequency), mA, replaced where ``fitted``; the command
        amplitude (0 outside ``fitted``), mA; the loop time constant, s.
    """
    n = x.size
    period = fs / freq
    pad = math.ceil(2.0 * float(period[zone].max())) + 8
    f_ref = float(np.median(freq[zone]))
    segs: list[tuple[int, int]] = []
    for lo, hi in runs(zone):  # close gaps shorter than the padding: fewer, longer segments
        if segs and lo - segs[-1][1] < pad:
            segs[-1] = (segs[-1][0], hi)
        else:
            segs.append((lo, hi))

    def run(lo: int, hi: int, wt: float):
        """Fit samples lo:hi (padded) with the loop at 2πf_ref·τ = wt."""
        a, b = max(lo - pad, 0), min(hi + pad, n)
        f = freq[a:b]
        gain = 1.0 / np.hypot(1.0, wt * f / f_ref)
        tau = wt / (2.0 * math.pi * f_ref) * fs  # samples
        th = theta[a:b] + np.arctan(wt * f / f_ref)  # the command leads the measured current
        span = round(max(2.0 * float(np.median(period[a:b])), _SPAN_S * fs))
        i_est, a_est, res, ok = _fit(
            x[a:b], th, span, nominal[a:b], amplitude[a:b] / gain, tau, waveform
        )
        return slice(lo - a, hi - a), i_est, a_est, res, ok, gain, (a, b)

    # τ from the chunks of the zone with the deepest clipping of the largest dither (most
    # distorted by the loop): the lag is a property of the driver, one per trace.
    pieces = [(s, min(s + _TAU_CHUNK, e)) for s0, e in segs for s in range(s0, e, _TAU_CHUNK)]
    pieces = [p for p in pieces if p[1] - p[0] >= min(_TAU_CHUNK, pad)]
    depth = np.clip(1.0 - nominal / np.maximum(amplitude, 1e-9), 0.0, 1.0) * amplitude
    score = [float(np.sum(depth[lo:hi])) for lo, hi in pieces]
    pieces = [pieces[k] for k in np.argsort(score)[::-1][: _TAU_SAMPLES // _TAU_CHUNK]]

    def cost(wt: float) -> float:  # mean squared residual (always from the same start)
        total, count = 0.0, 0
        for piece in pieces:
            core, _, _, res, ok, _, _ = run(*piece, wt)
            total += float(np.sum(res[core][ok[core]] ** 2))
            count += int(np.sum(ok[core]))
        return total / max(count, 1)

    wt = _argmin_1d(cost, np.linspace(0.0, _WT_MAX, 5)) if pieces else 0.0

    i_out, a_out = nominal.copy(), amplitude.copy()
    a_cmd = np.zeros(n)
    fitted = np.zeros(n, dtype=bool)
    for lo, hi in [(s, min(s + _BLOCK, e)) for s0, e in segs for s in range(s0, e, _BLOCK)]:
        core, i_est, a_est, _, ok, gain, (a, b) = run(lo, hi, wt)
        a_meas = dither_period_mean(a_est * gain, smooth[a:b])
        sel = ok[core] & zone[lo:hi]
        i_out[lo:hi] = np.where(sel, i_est[core], i_out[lo:hi])
        a_out[lo:hi] = np.where(sel, a_meas[core], a_out[lo:hi])
        a_cmd[lo:hi] = np.where(sel, a_est[core], 0.0)
        fitted[lo:hi] = sel
    return i_out, a_out, fitted, a_cmd, wt / (2.0 * math.pi * f_ref)
