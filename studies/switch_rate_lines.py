"""How switch currents move with the ramp rate, read off the data alone (no model).

For each dither setting of the held-back-rate datasets (ramps fast 2.5 s, 5 s, 20 s, slow
40 s; ``studies/latch_event.py`` writes them), the latch-on and latch-off command currents
are found from the measured dither-period-mean pressure (latched: within 1 bar of line
pressure). The switch currents at the two trained rates (fast, slow) are then interpolated
to the held-back 5 s and 20 s rates along ``r**p`` for a few powers ``p`` (``p = 1``: a
straight line in the rate, what the local latch-event law assumes per setting) and the
mean absolute miss is printed per dataset and direction. Nothing is chosen here; it shows
what a per-setting law can reach and where the rate dependence is not a straight line.

Usage: ``python studies/switch_rate_lines.py --data DIR [--powers 1,0.85,0.7,0.5]``
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

#: Ramp label → ramp duration (s) of the held-back-rate datasets.
RAMP_S = {"fast": 2.5, "r5": 5.0, "r20": 20.0, "slow": 40.0}


def switch_currents(trace) -> tuple[float, float]:
    """Latch-on and latch-off command current (mA) of one ramp experiment (NaN if absent)."""
    from clutchlab.data import dither_period_mean, dither_period_samples

    n = dither_period_samples(trace)
    p = dither_period_mean(trace.get("clutch_pressure_bar"), n)
    line = dither_period_mean(trace.get("line_pressure_bar"), n)
    cmd = np.asarray(trace.get("current_cmd_mA"), dtype=float)
    latched = p > line - 1.0
    top = int(np.argmax(cmd))
    if not latched[:top].any() or not latched[top:].any():
        return float("nan"), float("nan")
    on = int(np.flatnonzero(latched[:top])[0])
    off = top + int(np.flatnonzero(latched[top:])[-1])
    return float(cmd[on]), float(cmd[off])


def misses(path: Path, powers: list[float]) -> dict[float, tuple[float, float]]:
    """Mean |miss| (mA) of latch-on and latch-off at the held-back rates, per power."""
    from clutchlab.data import load_dataset

    by_setting: dict[str, dict[str, tuple[float, float]]] = {}
    for t in load_dataset(path):
        setting = t.name.split("_", 1)[1]
        by_setting.setdefault(setting, {})[str(t.ramp)] = switch_currents(t)
    out = {}
    span = 1.0  # rates as 1/duration: the ramp span cancels in the interpolation weight
    r_slow, r_fast = span / RAMP_S["slow"], span / RAMP_S["fast"]
    for p in powers:
        err: dict[int, list[float]] = {0: [], 1: []}
        for v in by_setting.values():
            if not all(k in v for k in RAMP_S):
                continue
            for ramp in ("r5", "r20"):
                u = ((span / RAMP_S[ramp]) ** p - r_slow**p) / (r_fast**p - r_slow**p)
                for which in (0, 1):
                    a, b = v["slow"][which], v["fast"][which]
                    err[which].append(abs(a + u * (b - a) - v[ramp][which]))
        out[p] = (float(np.nanmean(err[0])), float(np.nanmean(err[1])))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, required=True, help="folder of *_rates_s* datasets")
    ap.add_argument("--powers", default="1,0.85,0.7,0.5")
    args = ap.parse_args(argv)
    powers = [float(p) for p in args.powers.split(",")]
    print("mean |miss| (mA) latch-on / latch-off at the held-back 5 s and 20 s ramps")
    for path in sorted(args.data.glob("*_rates_s*")):
        row = misses(path, powers)
        print(
            f"{path.name:32s} "
            + "  ".join(f"p={p}: {on:5.1f} / {off:5.1f}" for p, (on, off) in row.items()),
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
