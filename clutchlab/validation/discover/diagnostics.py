"""Residual diagnostics: against each signal, lagged cross-correlation, spectrum, whiteness.

All on the kept (snap-free) training residuals of :class:`~.residuals.ResidualSet`
unless stated otherwise. The *signature* of a residual is the list of signals whose
binned conditional mean explains a sizeable part of it (correlation ratio η²).

A poor base fit leaves a large residual that follows the current and its direction of
travel (a misplaced characteristic or hysteresis), and a missing effect that follows
another signal (line pressure, oil temperature, the dither) is a small part of it. So
for every signal that is not the current, its direction or the pressure they set, η² is
also measured on what a flexible map of the current and its direction leaves: the
residual minus its mean per (current quantile bin × direction of travel), pooled over
the experiments (:func:`current_map_residual`). A signal that moves independently of the
ramp (line-pressure wander) keeps its share there; one the ramp fixes (an oil warming
through every run) does not, and no statistic on these data can separate it. A signal also
enters the signature by its partial correlation in the regulated region beyond each
experiment's own map (:mod:`.partial`), which sees a coupling of a few hundredths of a bar
under a misfit that differs from one ramp rate to the next.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
from scipy.signal import welch
from scipy.stats import chi2

from .partial import (
    CURRENT_DETERMINED_R2,
    MIN_REGULATED,
    current_determined_share,
    partial_hit,
    quantile_bins,
    regulated_mask,
    regulated_partial,
)
from .residuals import SIGNALS, ResidualSet, effective_size, integrated_time

__all__ = [
    "RAMP_BOUND_R2",
    "Diagnostics",
    "current_map_residual",
    "diagnose",
    "ramp_bound",
    "signal_association",
]

#: Quantile bins of a continuous signal for the correlation ratio.
N_BINS = 12
#: A signal enters the signature when its bias-corrected η² reaches this.
SIGNATURE_ETA2 = 0.1
#: Signals whose lagged cross-correlation with the residual is reported.
LAGGED = ("didt_mA_s", "dpdt_bar_s")
#: Signals the flexible map of the current and its direction stands for (their η² is
#: measured on the residual itself only).
MAP_SIGNALS = ("current_mA", "didt_mA_s", "didt_sign", "pressure_bar", "dpdt_bar_s")
#: Quantile bins of the current in that map (times the direction of travel: −1, 0, +1).
MAP_CURRENT_BINS = 24
#: A signal outside that map moves with the ramp when a map of the current and its direction
#: explains at least this share of its variance in the regulated region (and less than
#: :data:`~.partial.CURRENT_DETERMINED_R2`, above which the current sets it). Set between the
#: shares measured on the zoo's datasets in session 29 (line pressure 0.21–0.25, an oil at a
#: level per setting ≤ 0.003, an oil warming through every run 0.885–0.887).
RAMP_BOUND_R2 = 0.5


def _eta2(r: np.ndarray, x: np.ndarray, n_eff: float) -> tuple[float, list[dict]]:
    """Bias-corrected correlation ratio of ``r`` on ``x`` and the binned means."""
    values = np.unique(x)
    if values.size <= 1:
        return 0.0, []
    if values.size <= N_BINS:
        labels = np.searchsorted(values, x)
        edges = [(float(v), float(v)) for v in values]
    else:
        q = np.unique(np.quantile(x, np.linspace(0, 1, N_BINS + 1)))
        labels = np.clip(np.searchsorted(q, x, side="right") - 1, 0, len(q) - 2)
        edges = [(float(q[k]), float(q[k + 1])) for k in range(len(q) - 1)]
    total = float(np.sum((r - r.mean()) ** 2))
    if total <= 0:
        return 0.0, []
    between, bins = 0.0, []
    for k, (lo, hi) in enumerate(edges):
        sel = labels == k
        if not np.any(sel):
            continue
        m = float(r[sel].mean())
        between += sel.sum() * (m - r.mean()) ** 2
        bins.append({"lo": lo, "hi": hi, "mean_bar": m, "n": int(sel.sum())})
    eta2 = between / total
    b = len(bins)
    adj = eta2 - (b - 1) / max(n_eff - b, 1.0) * (1.0 - eta2)
    return float(max(adj, 0.0)), bins


def _constant(x: np.ndarray) -> bool:
    return x.size < 3 or np.ptp(x) <= 1e-9 * (1.0 + abs(float(np.mean(x))))


def current_map_residual(res: ResidualSet) -> np.ndarray:
    """The kept residual minus what a flexible map of the current and its direction explains.

    The map is the residual's mean per cell of (:data:`MAP_CURRENT_BINS` quantile bins of
    the nominal current × the direction of travel, −1 / 0 / +1), pooled over the
    experiments, so that what repeats with the ramp is removed and what moves
    independently of it (from one experiment to the next, or within one) is kept.

    Parameters
    ----------
    res : ResidualSet
        Residuals (bar) and signals.

    Returns
    -------
    numpy.ndarray
        Bar, one value per kept residual.
    """
    r = res.r[res.keep]
    cur = res.signals["current_mA"][res.keep]
    if r.size == 0 or _constant(cur):
        return r - (r.mean() if r.size else 0.0)
    k, _ = quantile_bins(cur, MAP_CURRENT_BINS)
    cell = k * 3 + (np.sign(res.signals["didt_sign"][res.keep]).astype(int) + 1)
    sums = np.bincount(cell, weights=r)
    counts = np.bincount(cell)
    return r - (sums / np.maximum(counts, 1))[cell]


def ramp_bound(res: ResidualSet) -> dict[str, float]:
    """Logged signals that move with the ramp in every run.

    A signal outside :data:`MAP_SIGNALS` of which a map of the current and its direction
    (:func:`~.partial.current_determined_share`, pooled over the experiments) explains
    between :data:`RAMP_BOUND_R2` and :data:`~.partial.CURRENT_DETERMINED_R2` of the variance
    in the regulated region (:func:`~.partial.regulated_mask`, where the clutch pressure
    depends on the circuit; the share is that of :func:`~.partial.regulated_partial`'s test):
    an oil that warms through every run, a supply that sags with the current. The current
    map removes it with any misfit in the current, so no statistic on these data can tell its
    effect from such a misfit; runs in which it differs at the same current can.

    Parameters
    ----------
    res : ResidualSet
        Residuals and signals.

    Returns
    -------
    dict
        Signal name -> the share (0–1), largest first.
    """
    keep = res.keep
    regulated = regulated_mask(res)
    cur = res.signals["current_mA"][keep][regulated]
    if int(regulated.sum()) < MIN_REGULATED or _constant(cur):
        return {}
    direction = np.sign(res.signals["didt_sign"][keep][regulated]).astype(int)
    out = {}
    for name in SIGNALS:
        x = np.asarray(res.signals[name][keep][regulated], dtype=float)
        if name in MAP_SIGNALS or _constant(x):
            continue
        share = current_determined_share(x, cur, direction)
        if RAMP_BOUND_R2 <= share < CURRENT_DETERMINED_R2:
            out[name] = float(share)
    return dict(sorted(out.items(), key=lambda kv: -kv[1]))


def signal_association(res: ResidualSet, n_eff: float | None = None) -> list[dict]:
    """Residual against each signal: Pearson correlation and bias-corrected η².

    For a signal outside :data:`MAP_SIGNALS` also ``eta2_beyond_current``: its η² on
    :func:`current_map_residual` (bias-corrected with that residual's own effective size),
    the share of what the current and its direction leave that the signal explains; and
    ``partial_regulated``: :func:`~.partial.regulated_partial` (None where it cannot be
    measured).

    Parameters
    ----------
    res : ResidualSet
        Residuals and signals.
    n_eff : float, optional
        Effective number of independent residuals (for the η² bias correction).

    Returns
    -------
    list of dict
        ``signal``, ``unit``, ``description``, ``corr``, ``eta2``, ``bins``,
        ``eta2_beyond_current`` and ``partial_regulated`` (None for the map's own
        signals); largest η² of the two first.
    """
    r = res.r[res.keep]
    if n_eff is None:
        n_eff = res.effective()[0]
    rest = current_map_residual(res)
    n_rest = effective_size(rest, res.kept_slices)[0]
    out = []
    for name, (unit, desc) in SIGNALS.items():
        x = res.signals[name][res.keep]
        beyond = None if name in MAP_SIGNALS else 0.0
        partial = None
        if _constant(x):
            corr, eta2, bins = 0.0, 0.0, []
        else:
            corr = float(np.corrcoef(r, x)[0, 1]) if np.std(r) > 0 else 0.0
            eta2, bins = _eta2(r, x, n_eff)
            if beyond is not None:
                beyond, _ = _eta2(rest, x, n_rest)
                partial = regulated_partial(res, name)
        out.append(
            {
                "signal": name,
                "unit": unit,
                "description": desc,
                "corr": corr,
                "eta2": eta2,
                "bins": bins,
                "eta2_beyond_current": beyond,
                "partial_regulated": partial,
            }
        )
    out.sort(key=lambda d: -_strength(d))
    return out


def _strength(assoc: dict) -> float:
    """The larger of a signal's η² on the residual and beyond the current map."""
    return max(assoc["eta2"], assoc.get("eta2_beyond_current") or 0.0)


def _in_signature(assoc: dict) -> bool:
    """η² of at least :data:`SIGNATURE_ETA2`, or a partial correlation in the regulated
    region that :func:`~.partial.partial_hit` accepts."""
    return _strength(assoc) >= SIGNATURE_ETA2 or partial_hit(assoc.get("partial_regulated"))


def _lagged(res: ResidualSet, name: str, max_lag: int) -> tuple[np.ndarray, np.ndarray]:
    """Pooled normalized cross-correlation ``corr(r(t), x(t − lag))`` for lags ±max_lag."""
    lags = np.arange(-max_lag, max_lag + 1)
    num = np.zeros(len(lags))
    rr = xx = 0.0
    for a, b in res.slices:
        r = res.r[a:b] - res.r[a:b].mean()
        x = res.signals[name][a:b] - res.signals[name][a:b].mean()
        rr += float(r @ r)
        xx += float(x @ x)
        for k, lag in enumerate(lags):
            if abs(lag) >= len(r):
                continue
            num[k] += float(r[lag:] @ x[: len(x) - lag]) if lag >= 0 else float(r[:lag] @ x[-lag:])
    den = np.sqrt(rr * xx)
    return lags, (num / den if den > 0 else num)


def _ljung_box(res: ResidualSet, n_lags: int = 20) -> tuple[float, int, float, int]:
    """Pooled Ljung–Box test on residuals one averaging window apart (no overlap).

    The period mean makes neighbouring residuals correlated even for white sensor
    noise; taking every ``ceil(window / decimation)``-th residual removes that.
    Returns the statistic, degrees of freedom, p-value and the stride used.
    """
    stride = max(int(np.ceil(res.n_period)), 1)
    q, dof = 0.0, 0
    for a, b in res.kept_slices:
        x = res.r[res.keep][a:b][::stride]
        n = len(x)
        h = min(n_lags, n // 5)
        if h < 1:
            continue
        x = x - x.mean()
        den = float(x @ x)
        if den <= 0:
            continue
        rho = np.array([float(x[k:] @ x[:-k]) / den for k in range(1, h + 1)])
        q += n * (n + 2) * float(np.sum(rho**2 / (n - np.arange(1, h + 1))))
        dof += h
    p = float(chi2.sf(q, dof)) if dof else 1.0
    return q, dof, p, stride


@dataclass
class Diagnostics:
    """What the residual follows.

    Attributes
    ----------
    rms_bar : float
        RMS of the kept residuals (bar).
    n, n_eff : int, float
        Kept residuals; effective number of independent ones.
    tau_samples : float
        Mean integrated autocorrelation time (residual samples).
    associations : list of dict
        :func:`signal_association`.
    cross_correlation : dict
        Per lagged signal: ``lag_s`` and ``corr`` at the peak |corr|, and the curves.
    spectrum : dict
        Welch power spectral density of the residual (``freq_Hz``, ``psd_bar2_Hz``)
        averaged over experiments, and the fraction of power below 1 Hz.
    whiteness : dict
        Ljung–Box ``statistic``, ``dof``, ``p_value``, ``stride`` and ``white`` (p ≥ 0.01).
    signature : list of str
        Signals with η² ≥ :data:`SIGNATURE_ETA2` on the residual or beyond the current
        map (``eta2_beyond_current``), or with a partial correlation in the regulated
        region beyond each experiment's map (``partial_regulated``, :mod:`.partial`),
        strongest η² first; a signal that moves with one already listed (|corr| > 0.98
        on these data) is left out.
    aliases : dict
        Signals indistinguishable on these data: name -> the signal standing for it.
    ramp_bound : dict
        :func:`ramp_bound`: signals that move with the ramp in every run -> the share of
        their variance the current and its direction explain.
    """

    rms_bar: float
    n: int
    n_eff: float
    tau_samples: float
    associations: list[dict] = field(default_factory=list)
    cross_correlation: dict = field(default_factory=dict)
    spectrum: dict = field(default_factory=dict)
    whiteness: dict = field(default_factory=dict)
    signature: list[str] = field(default_factory=list)
    aliases: dict[str, str] = field(default_factory=dict)
    ramp_bound: dict[str, float] = field(default_factory=dict)

    def ramp_note(self) -> str:
        """What the signals that move with the ramp mean for this residual ("" if none)."""
        if not self.ramp_bound:
            return ""
        which = ", ".join(f"{k} ({v:.0%})" for k, v in self.ramp_bound.items())
        one = len(self.ramp_bound) == 1
        return (
            f"{which} {'moves' if one else 'move'} with the ramp in every run (that share of "
            f"{'its' if one else 'their'} variance in the regulated region follows the current "
            f"and its direction): these data cannot tell {'its' if one else 'their'} effect "
            f"from a misfit in the current; runs in which {'it differs' if one else 'they differ'} "
            "at the same current can"
        )

    def summary(self) -> str:
        """One line: what the residual follows."""
        if not self.signature:
            follows = (
                f"no single signal (η² < {SIGNATURE_ETA2:.2f}, "
                "no regulated-region partial correlation)"
            )
        else:
            eta = {a["signal"]: a for a in self.associations}
            follows = ", ".join(_describe(eta[s]) for s in self.signature)
        xc = "; ".join(
            f"peak corr with {k} {v['corr']:+.2f} at lag {v['lag_s'] * 1e3:+.0f} ms"
            for k, v in self.cross_correlation.items()
        )
        if self.aliases:
            same = ", ".join(f"{a} ≡ {b}" for a, b in self.aliases.items())
            follows += f" (aliased on these data: {same})"
        white = "white" if self.whiteness.get("white") else "not white"
        p = self.whiteness.get("p_value", 1.0)
        ramp = self.ramp_note()
        return (
            f"RMS {self.rms_bar:.4f} bar without the samples near latch snaps (the training "
            f"RMSE includes them), {white} (Ljung–Box p {p:.2g}, autocorrelation time "
            f"τ {self.tau_samples:.1f} samples); follows {follows}; {xc}"
            + (f"; {ramp}" if ramp else "")
        )

    def to_dict(self, curves: bool = False) -> dict:
        """JSON-ready dict (without the spectrum and correlation curves unless ``curves``)."""
        d = asdict(self)
        if not curves:
            d["spectrum"] = {k: v for k, v in d["spectrum"].items() if not isinstance(v, list)}
            d["cross_correlation"] = {
                k: {kk: vv for kk, vv in v.items() if not isinstance(vv, list)}
                for k, v in d["cross_correlation"].items()
            }
        return d


def _describe(assoc: dict) -> str:
    partial = assoc.get("partial_regulated")
    if _strength(assoc) < SIGNATURE_ETA2 and partial_hit(partial):
        return (
            f"{assoc['signal']} (partial r {partial['rho']:+.2f}, z {partial['z']:+.1f} in the "
            "regulated region beyond each experiment's current map)"
        )
    beyond = assoc.get("eta2_beyond_current")
    if beyond is not None and beyond > assoc["eta2"]:
        return f"{assoc['signal']} (η² {beyond:.2f} beyond the current and its direction)"
    return f"{assoc['signal']} (η² {assoc['eta2']:.2f}, r {assoc['corr']:+.2f})"


def diagnose(res: ResidualSet, max_lag_s: float = 0.1) -> Diagnostics:
    """Residual diagnostics of ``res``.

    Parameters
    ----------
    res : ResidualSet
        Residuals (bar) and the signals at the same samples.
    max_lag_s : float
        Largest lag of the cross-correlations (s).

    Returns
    -------
    Diagnostics
    """
    n_eff, tau = res.effective()
    assoc = signal_association(res, n_eff)
    max_lag = max(round(max_lag_s / res.row_dt_s), 1) if res.row_dt_s > 0 else 1
    xcorr = {}
    for name in LAGGED:
        lags, c = _lagged(res, name, max_lag)
        k = int(np.argmax(np.abs(c)))
        xcorr[name] = {
            "lag_s": float(lags[k] * res.row_dt_s),
            "corr": float(c[k]),
            "lags_s": (lags * res.row_dt_s).tolist(),
            "values": c.tolist(),
        }
    spectrum: dict = {}
    if res.row_dt_s > 0:
        fs = 1.0 / res.row_dt_s
        psds, freq = [], None
        for a, b in res.slices:
            x = res.r[a:b]
            if len(x) < 16:
                continue
            freq, p = welch(x - x.mean(), fs=fs, nperseg=min(256, len(x)))
            psds.append(p)
        if psds:
            n_f = min(len(p) for p in psds)
            psd = np.mean([p[:n_f] for p in psds], axis=0)
            freq = freq[:n_f]
            total = float(np.sum(psd))
            spectrum = {
                "freq_Hz": freq.tolist(),
                "psd_bar2_Hz": psd.tolist(),
                "below_1Hz_fraction": float(np.sum(psd[freq < 1.0]) / total) if total else 0.0,
                "peak_Hz": float(freq[int(np.argmax(psd))]),
            }
    q, dof, p, stride = _ljung_box(res)
    rk = res.r[res.keep]
    aliases = _aliases(res)
    return Diagnostics(
        rms_bar=float(np.sqrt(np.mean(rk**2))) if rk.size else 0.0,
        n=int(rk.size),
        n_eff=float(n_eff),
        tau_samples=float(tau),
        associations=assoc,
        cross_correlation=xcorr,
        spectrum=spectrum,
        whiteness={
            "statistic": q,
            "dof": dof,
            "p_value": p,
            "stride": stride,
            "white": bool(p >= 0.01),
            "tau_per_experiment": [
                integrated_time(res.r[res.keep][a:b]) for a, b in res.kept_slices
            ],
        },
        signature=[a["signal"] for a in assoc if _in_signature(a) and a["signal"] not in aliases],
        aliases=aliases,
        ramp_bound=ramp_bound(res),
    )


def _aliases(res: ResidualSet, limit: float = 0.98) -> dict[str, str]:
    """Signals that move with an earlier one (|corr| > ``limit`` on the kept samples)."""
    kept: dict[str, np.ndarray] = {}
    out = {}
    for name in SIGNALS:
        x = res.signals[name][res.keep]
        sd = float(np.std(x))
        if not x.size or sd <= 1e-9 * (1.0 + abs(float(np.mean(x)))):
            continue
        z = (x - x.mean()) / sd
        twin = next((n for n, c in kept.items() if abs(float(np.mean(z * c))) > limit), None)
        if twin is None:
            kept[name] = z
        else:
            out[name] = twin
    return out
