"""Asymmetric (fill / drain) lag of the nominal current, chosen inside the training set.

Does a drain time constant ``K`` times the fill one, ``K`` chosen by :func:`select_lag`'s own
leave-one-ramp-rate-out score on the fast + slow ramps, predict the held-back training-side
rates better than today's symmetric lag (``K = 1``)? The lag is swapped in for the study only
(``first_order_lag`` in :mod:`clutchlab.residual_ml.lag` and ``.features``); the library is
unchanged.

Usage: ``python studies/asymmetric_lag.py NAME[,NAME...] OUT.json [--root=DIR]`` with the
rates datasets ``DIR/NAME`` (default ``/work/runs/rates``; fast, r5, r20, slow ramps; no
medium ramp exists in them). Result (session 22, BENCHMARKS "Latch-timing and
rate-interpolation"): the rule is not met, nothing follows.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np
from numba import njit

import clutchlab.residual_ml.features as featmod
import clutchlab.residual_ml.lag as lagmod
from clutchlab.data import dither_period_mean, dither_period_samples, load_dataset
from clutchlab.residual_ml import GPWithDerivative, SVCPartitionedGP, target_pressure

RULE = """\
RULE (printed first; written before any number of this study was seen):
Per dataset (rates datasets: stand + 4 zoo plants x seeds 0-2; train fast + slow; score r5 +
r20, the held-back training-side rates), for K in {0.5, 0.7, 1, 1.4, 2} (tau_drain = K
tau_fill, tau chosen by select_lag as today): auto-K = argmin over K of select_lag's LORO
score at its chosen tau (fast + slow only). An implementation follows only if, for BOTH
paper_svc_gp and gp_didt, auto-K's held-back RMSE (mean over seeds) is lower than K = 1's on
>= 4 of 5 circuits and no dataset is worse than K = 1 by more than 5 %."""

KS = (0.5, 0.7, 1.0, 1.4, 2.0)
_K = [1.0]


@njit(cache=True)
def _asymmetric(x, a_fill, a_drain):
    y = np.empty_like(x)
    prev = x[0]
    for i in range(x.size):
        a = a_fill if x[i] >= prev else a_drain
        prev = a * prev + (1.0 - a) * x[i]
        y[i] = prev
    return y


def asymmetric_lag(x: np.ndarray, tau_s: float, sample_rate_Hz: float) -> np.ndarray:
    """First-order lag with τ (s) while the input is above the output, ``K``·τ below it."""
    x = np.asarray(x, dtype=float)
    if tau_s <= 0 or x.size == 0:
        return x.copy()
    fs = sample_rate_Hz
    return _asymmetric(x, np.exp(-1.0 / (tau_s * fs)), np.exp(-1.0 / (_K[0] * tau_s * fs)))


def _rmse(model, held) -> float:
    sse, n = 0.0, 0
    for t in held:
        e = dither_period_mean(model.predict(t), dither_period_samples(t)) - target_pressure(t)
        sse += float(e @ e)
        n += e.size
    return float(np.sqrt(sse / n))


def main() -> None:
    args = [a for a in sys.argv[1:] if not a.startswith("--root=")]
    root = next((a.split("=", 1)[1] for a in sys.argv[1:] if a.startswith("--root=")), None)
    root = root or "/work/runs/rates"
    lagmod.first_order_lag = asymmetric_lag
    featmod.first_order_lag = asymmetric_lag
    print(RULE, flush=True)
    out: dict = {}
    for name in args[0].split(","):
        ds = load_dataset(f"{root}/{name}")
        train = [t for t in ds if t.ramp in ("fast", "slow")]
        held = [t for t in ds if t.ramp in ("r5", "r20")]
        row = {}
        for k in KS:
            _K[0] = k
            r = {}
            for label, cls in (("paper_svc_gp", SVCPartitionedGP), ("gp_didt", GPWithDerivative)):
                t0 = time.perf_counter()
                m = cls().fit(train)
                sel = m.lag_selection_
                r[label] = {
                    "held": _rmse(m, held),
                    "loro": min(sel.scores.values()) if sel and sel.scores else None,
                    "tau": m.lag_s_,
                    "wall": time.perf_counter() - t0,
                }
            row[str(k)] = r
            print(name, k, {lab: round(v["held"], 4) for lab, v in r.items()}, flush=True)
        out[name] = row
        Path(args[1]).write_text(json.dumps(out, indent=1), encoding="utf-8")


if __name__ == "__main__":
    main()
