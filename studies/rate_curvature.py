"""How far from a straight line in the ramp rate the latch switches and the regulated band are,
read off four ramp rates (diagnosis only: nothing is chosen here).

A latch-event law trained on two ramp rates (fast + slow) has two events per dither setting and
direction, so it can only be a two-parameter curve in the rate: a straight line in ``r`` (the
default local law), or a line in ``r**p`` for a ``p`` fixed beforehand. Whether that can
interpolate to a third rate depends on the curvature, which two rates cannot show. The
held-back-rate datasets (ramps fast 2.5 s, 5 s, 20 s, slow 40 s; ``studies/latch_event.py``
writes them) can: for each dither setting this script fits ``x(r) = a + b·r**p`` to the four
rates (``r`` = 1 / ramp duration) by least squares, for

* the latch-on and latch-off command currents (mA; ``switch_rate_lines.switch_currents``),
* the regulated band's width (mA): the rising branch's current at a pressure level minus the
  falling branch's, at 2, 4 and 6 bar (median over the levels).

``p = 1`` is a straight line; ``p < 1`` concave (the change from the slow to a medium rate is
larger than a line through fast and slow gives). It prints, per dataset, the median ``p`` over
the settings and the largest residual of the fit (mA), and the miss of the straight line
through fast and slow at the 5 s and 20 s ramps (mean |miss|, mA).

Usage: ``python studies/rate_curvature.py --data DIR`` (DIR holds ``*_rates_s*`` folders).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares
from switch_rate_lines import RAMP_S, switch_currents  # the script's own folder is on sys.path

#: Pressure levels (bar) at which the regulated band's width is read.
LEVELS_BAR = (2.0, 4.0, 6.0)
#: Bounds of the fitted exponent.
P_BOUNDS = (0.2, 3.0)


def band_width(trace) -> float:
    """Median over :data:`LEVELS_BAR` of the rising branch's command current at the level
    minus the falling branch's (mA; period means, regulated samples only); NaN if absent."""
    from clutchlab.data import dither_period_mean, dither_period_samples

    n = dither_period_samples(trace)
    p = dither_period_mean(trace.get("clutch_pressure_bar"), n)
    line = dither_period_mean(trace.get("line_pressure_bar"), n)
    cmd = dither_period_mean(trace.get("current_cmd_mA"), n)
    top = int(np.argmax(cmd))
    regulated = p < line - 1.0
    widths = []
    for level in LEVELS_BAR:
        up = np.flatnonzero((p[:top] >= level) & regulated[:top])
        down = np.flatnonzero((p[top:] >= level) & regulated[top:])
        if len(up) and len(down):
            widths.append(cmd[up[0]] - cmd[top + down[-1]])
    return float(np.median(widths)) if widths else float("nan")


def power_fit(rates: np.ndarray, values: np.ndarray) -> tuple[float, float]:
    """Least-squares ``a + b·r**p`` through the points; ``(p, largest |residual|)``."""
    lo, hi = float(values[np.argmin(rates)]), float(values[np.argmax(rates)])
    slope = (hi - lo) / max(rates.max() - rates.min(), 1e-12)
    sol = least_squares(
        lambda th: th[0] + th[1] * rates ** th[2] - values,
        [lo - slope * rates.min(), slope, 1.0],
        bounds=([-np.inf, -np.inf, P_BOUNDS[0]], [np.inf, np.inf, P_BOUNDS[1]]),
    )
    return float(sol.x[2]), float(np.max(np.abs(sol.fun)))


def line_miss(rates: dict[str, float], values: dict[str, float]) -> float:
    """Mean |miss| (mA) at the 5 s and 20 s ramps of the straight line through fast and slow."""
    r_s, r_f = rates["slow"], rates["fast"]
    miss = []
    for ramp in ("r5", "r20"):
        u = (rates[ramp] - r_s) / (r_f - r_s)
        miss.append(values["slow"] + u * (values["fast"] - values["slow"]) - values[ramp])
    return float(np.mean(np.abs(miss)))


def curvature(path: Path) -> dict[str, tuple[float, float, float]]:
    """Per quantity (``on``, ``off``, ``band``): median ``p``, largest residual (mA) and mean
    straight-line miss (mA) over the dither settings with all four rates."""
    from clutchlab.data import load_dataset

    rows: dict[str, dict[str, dict[str, float]]] = {}
    for t in load_dataset(path):
        ramp = str(t.ramp)
        if ramp not in RAMP_S:
            continue
        on, off, _, _ = switch_currents(t)
        setting = rows.setdefault(t.name.split("_", 1)[1], {})
        setting[ramp] = {"on": on, "off": off, "band": band_width(t)}
    rates = {k: 1.0 / v for k, v in RAMP_S.items()}
    out = {}
    for what in ("on", "off", "band"):
        ps, res, miss = [], [], []
        for setting in rows.values():
            if set(setting) != set(RAMP_S):
                continue
            vals = {k: setting[k][what] for k in RAMP_S}
            if not all(np.isfinite(v) for v in vals.values()):
                continue
            r = np.array([rates[k] for k in RAMP_S])
            p, worst = power_fit(r, np.array([vals[k] for k in RAMP_S]))
            ps.append(p)
            res.append(worst)
            miss.append(line_miss(rates, vals))
        out[what] = (
            (float(np.median(ps)), float(np.max(res)), float(np.mean(miss)))
            if ps
            else (float("nan"),) * 3
        )
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, required=True, help="folder of *_rates_s* datasets")
    args = ap.parse_args(argv)
    print(
        "per dataset and quantity: median exponent p of a + b·r^p over the settings "
        "(1 = straight line in the rate) / largest residual of that fit (mA) / mean miss of "
        "the straight line through fast + slow at the 5 s and 20 s ramps (mA)"
    )
    for path in sorted(args.data.glob("*_rates_s*")):
        row = curvature(path)
        print(
            f"{path.name:32s} "
            + "   ".join(f"{k} p {p:4.2f} / {r:4.1f} / {m:4.1f}" for k, (p, r, m) in row.items()),
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
