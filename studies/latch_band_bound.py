"""How much of a fitted model's held-back error a latch band law could remove (issue 16,
must-show 1; diagnosis only, nothing is chosen).

On datasets with held-back training-side ramps (fast 2.5 s, 5 s, 20 s, slow 40 s; no medium
ramp), for a physics fit made on fast + slow: every snap of the measured dither-period-mean
clutch pressure (|dp/dt| > 60 bar/s) is matched by the time shift of the model's prediction
that minimizes the squared error in a window around it (± 0.4 / 0.6 / 1.2 / 1.8 s on the
2.5 / 5 / 20 / 40 s ramps). The shift in nominal current, ``d = I(t + shift) − I(t)`` (mA,
model minus measured), is the error of the model's switch current at that snap.

The law tried on paper: ``d = X b`` per switch direction, with
``X = [1, a, a·u, a·u²]``, ``a`` the logged dither amplitude at the snap (mA) and
``u = (f − 50 Hz) / 20 Hz`` — switch currents that move with the dither amplitude, by an
amount that depends on the dither frequency (a latch that must see its pilot beyond a
threshold for a dwell time, or through a valve that filters the dither, does that). ``b`` is
learnt on the *training* snaps only (slow ramps; or fast + slow) and applied to the held-back
5 s + 20 s snaps as a time shift ``d̂ / (dI/dt)``. Printed per dataset: the held-back RMSE of
the fit as it is, with the law, and with every held-back snap perfectly aligned (the end no
switch-current law can pass). Also printed, not decided on: the same with session 54's E2
form ``[1, a]`` and with offsets that depend on the frequency alone added
(``[1, u, u², a, a·u, a·u²]``), both learnt on the slow snaps. A pure time shift of a
window is an idealization of what a law in the model would do: it bounds, it does not
measure, the law.

Usage: ``python studies/latch_band_bound.py DATA FIT.json [DATA FIT.json ...]``
"""

from __future__ import annotations

import argparse

import numpy as np

from clutchlab.data import dither_period_mean, dither_period_samples, load_dataset
from clutchlab.physics.fit import PhysicsFitter

#: Half-width (s) of the window a snap is matched in, per ramp label.
WINDOW_S = {"fast": 0.4, "r5": 0.6, "r20": 1.2, "slow": 1.8}
#: |d(period mean)/dt| above which a sample belongs to a measured snap, bar/s.
SNAP_RATE = 60.0
HELD_BACK = ("r5", "r20")
RULE = """\
Reading (written before the runs, RULE.md W1 of session 55): if the law learnt on the slow or
on the fast + slow snaps gives a held-back RMSE <= 0.15 bar on >= 3 of the 4 first rows
(quadratic_play s0, stribeck_supply s0, saturating_lugre s1, preisach_accumulator s1), the law
is worth building into the model; if on <= 1 row, a static law of this form is not the path."""


def _snaps(dm: np.ndarray, fs: float) -> list[int]:
    """Centre sample of each measured snap (runs of fast change > 0.5 s apart)."""
    groups: list[list[int]] = []
    for i in np.flatnonzero(np.abs(dm) > SNAP_RATE):
        if groups and i - groups[-1][-1] <= 0.5 * fs:
            groups[-1].append(int(i))
        else:
            groups.append([int(i)])
    return [g[len(g) // 2] for g in groups]


def experiment_snaps(trace, fitter) -> dict:
    """The matched snaps of one experiment and its squared period-mean error."""
    n = dither_period_samples(trace)
    fs = trace.sample_rate_Hz
    meas = dither_period_mean(np.asarray(trace.get("clutch_pressure_bar"), float), n)
    pred = dither_period_mean(np.asarray(fitter.predict(trace), float), n)
    name = "current_cmd_mA" if trace.has("current_cmd_mA") else "current_mA"
    cur = dither_period_mean(np.asarray(trace.get(name), float), n)
    amp = dither_period_mean(np.asarray(trace.get("dither_amp_mA"), float), n)
    freq = float(np.nanmedian(trace.get("dither_freq_Hz")))
    d_cur = np.gradient(cur) * fs
    d_meas = np.gradient(meas) * fs
    half = int(WINDOW_S[trace.ramp] * fs)
    snaps = []
    for c in _snaps(d_meas, fs):
        lo, hi = max(c - half, 0), min(c + half, meas.size)
        sse = {
            s: float(np.sum((pred[lo + s : hi + s] - meas[lo:hi]) ** 2))
            for s in range(-half, half + 1)
            if lo + s >= 0 and hi + s <= pred.size
        }
        best = min(sse, key=sse.__getitem__)
        snaps.append(
            {
                "kind": "on" if d_meas[c] > 0 else "off",
                "sse": sse,
                "shift": best,
                "d_mA": float(cur[min(c + best, cur.size - 1)] - cur[c]),
                "amp_mA": float(amp[c]),
                "freq_Hz": freq,
                "dIdt": float(d_cur[c]),
            }
        )
    return {
        "ramp": trace.ramp,
        "fs": fs,
        "sse": float(np.sum((pred - meas) ** 2)),
        "n": meas.size,
        "snaps": snaps,
    }


#: The law's forms: the rule's; session 54's E2 (amplitude only); and the rule's with
#: offsets that depend on the frequency alone (added after the rule, reported, not decided on).
FORMS = {
    "rule": lambda a, u: [1.0, a, a * u, a * u * u],
    "E2": lambda a, u: [1.0, a],
    "freq": lambda a, u: [1.0, u, u * u, a, a * u, a * u * u],
}


def features(snap: dict, form: str = "rule") -> np.ndarray:
    """The law's features of one snap (``FORMS``; the rule's ``[1, a, a·u, a·u²]``)."""
    u = (snap["freq_Hz"] - 50.0) / 20.0
    return np.array(FORMS[form](snap["amp_mA"], u))


def learn(exps: list[dict], ramps: tuple[str, ...], form: str = "rule") -> dict[str, np.ndarray]:
    """Least-squares law coefficients per switch direction from the snaps of ``ramps``."""
    coef = {}
    for kind in ("on", "off"):
        rows = [s for e in exps if e["ramp"] in ramps for s in e["snaps"] if s["kind"] == kind]
        a = np.array([features(s, form) for s in rows])
        y = np.array([s["d_mA"] for s in rows])
        coef[kind] = np.linalg.lstsq(a, y, rcond=None)[0]
    return coef


def held_back_rmse(exps: list[dict], shift_of) -> float:
    """Held-back period-mean RMSE (bar) with each held-back snap window shifted by
    ``shift_of(snap, experiment)`` samples (clipped to its window)."""
    total = count = 0.0
    for e in exps:
        if e["ramp"] not in HELD_BACK:
            continue
        sse = e["sse"]
        for s in e["snaps"]:
            k = int(np.clip(round(shift_of(s, e)), min(s["sse"]), max(s["sse"])))
            sse += s["sse"].get(k, s["sse"][0]) - s["sse"][0]
        total += sse
        count += e["n"]
    return float(np.sqrt(total / count))


def bound(data: str, fit: str) -> dict[str, float]:
    """The held-back RMSEs of one dataset and fit."""
    fitter = PhysicsFitter.load(fit)
    exps = [experiment_snaps(t, fitter) for t in load_dataset(data) if t.ramp in WINDOW_S]
    row = {
        "as fitted": held_back_rmse(exps, lambda s, e: 0),
        "perfect per snap": held_back_rmse(exps, lambda s, e: s["shift"]),
    }
    variants = {
        "law, slow": (("slow",), "rule"),
        "law, fast+slow": (("fast", "slow"), "rule"),
        "E2 form, slow": (("slow",), "E2"),
        "+freq, slow": (("slow",), "freq"),
    }
    for label, (ramps, form) in variants.items():
        coef = learn(exps, ramps, form)
        row[label] = held_back_rmse(
            exps,
            lambda s, e, c=coef, f=form: features(s, f) @ c[s["kind"]] / s["dIdt"] * e["fs"],
        )
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("pairs", nargs="+", help="DATA FIT.json pairs")
    args = ap.parse_args()
    if len(args.pairs) % 2:
        ap.error("give DATA FIT.json pairs")
    print(RULE, flush=True)
    cols = (
        "as fitted",
        "law, slow",
        "law, fast+slow",
        "E2 form, slow",
        "+freq, slow",
        "perfect per snap",
    )
    print(f"\n{'dataset':40s} " + " ".join(f"{c:>16s}" for c in cols))
    for data, fit in zip(args.pairs[::2], args.pairs[1::2], strict=True):
        row = bound(data, fit)
        print(f"{data[-40:]:40s} " + " ".join(f"{row[c]:16.4f}" for c in cols), flush=True)


if __name__ == "__main__":
    main()
