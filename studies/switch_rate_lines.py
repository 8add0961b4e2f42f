"""How switch currents move with the ramp rate, read off the data alone (no model).

For each dither setting of the held-back-rate datasets (ramps fast 2.5 s, 5 s, 20 s, slow
40 s; ``studies/latch_event.py`` writes them), the latch-on and latch-off command currents
are found from the measured dither-period-mean pressure (latched: within 1 bar of line
pressure). The switch currents at the two trained rates (fast, slow) are then interpolated
to the held-back 5 s and 20 s rates along ``r**p`` for a few powers ``p`` (``p = 1``: a
straight line in the rate, what the local latch-event law assumes per setting) and the
mean absolute miss is printed per dataset and direction. For ``p = 1`` it also prints how
the miss follows the line pressure at the switch (its deviation from the same straight-line
interpolation): correlation and slope (mA/bar). Nothing is chosen here; it shows what a
per-setting law can reach, where the rate dependence is not a straight line, and where the
switch moves with line pressure.

Usage: ``python studies/switch_rate_lines.py --data DIR [--powers 1,0.85,0.7,0.5]``
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

#: Ramp label → ramp duration (s) of the held-back-rate datasets.
RAMP_S = {"fast": 2.5, "r5": 5.0, "r20": 20.0, "slow": 40.0}


def switch_currents(trace) -> tuple[float, float, float, float]:
    """Latch-on and latch-off command current (mA) of one ramp experiment and the line
    pressure (bar, dither-period mean) at each (NaN if absent)."""
    from clutchlab.data import dither_period_mean, dither_period_samples

    n = dither_period_samples(trace)
    p = dither_period_mean(trace.get("clutch_pressure_bar"), n)
    line = dither_period_mean(trace.get("line_pressure_bar"), n)
    cmd = np.asarray(trace.get("current_cmd_mA"), dtype=float)
    latched = p > line - 1.0
    top = int(np.argmax(cmd))
    if not latched[:top].any() or not latched[top:].any():
        return (float("nan"),) * 4
    on = int(np.flatnonzero(latched[:top])[0])
    off = top + int(np.flatnonzero(latched[top:])[-1])
    return float(cmd[on]), float(cmd[off]), float(line[on]), float(line[off])


def misses(path: Path, powers: list[float]) -> tuple[dict, dict]:
    """Mean |miss| (mA) of latch-on and latch-off at the held-back rates, per power; and
    per direction, the correlation and slope (mA/bar) of the ``p = 1`` miss against the
    line pressure's deviation from its own straight-line interpolation."""
    from clutchlab.data import load_dataset

    by_setting: dict[str, dict[str, tuple[float, ...]]] = {}
    for t in load_dataset(path):
        setting = t.name.split("_", 1)[1]
        by_setting.setdefault(setting, {})[str(t.ramp)] = switch_currents(t)
    out, line_fit = {}, {}
    span = 1.0  # rates as 1/duration: the ramp span cancels in the interpolation weight
    r_slow, r_fast = span / RAMP_S["slow"], span / RAMP_S["fast"]
    for p in powers:
        err: dict[int, list[float]] = {0: [], 1: []}
        dev: dict[int, list[float]] = {0: [], 1: []}
        for v in by_setting.values():
            if not all(k in v for k in RAMP_S):
                continue
            for ramp in ("r5", "r20"):
                u = ((span / RAMP_S[ramp]) ** p - r_slow**p) / (r_fast**p - r_slow**p)
                for which in (0, 1):
                    a, b = v["slow"][which], v["fast"][which]
                    err[which].append(a + u * (b - a) - v[ramp][which])
                    la, lb = v["slow"][which + 2], v["fast"][which + 2]
                    dev[which].append(la + u * (lb - la) - v[ramp][which + 2])
        out[p] = tuple(float(np.nanmean(np.abs(err[w]))) for w in (0, 1))
        if p == 1.0:
            for w, name in ((0, "on"), (1, "off")):
                e, d = np.asarray(err[w]), np.asarray(dev[w])
                ok = np.isfinite(e) & np.isfinite(d)
                if ok.sum() > 2 and np.std(d[ok]) > 0 and np.std(e[ok]) > 0:
                    line_fit[name] = (
                        float(np.corrcoef(e[ok], d[ok])[0, 1]),
                        float(np.polyfit(d[ok], e[ok], 1)[0]),
                    )
    return out, line_fit


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, required=True, help="folder of *_rates_s* datasets")
    ap.add_argument("--powers", default="1,0.85,0.7,0.5")
    args = ap.parse_args(argv)
    powers = [float(p) for p in args.powers.split(",")]
    print("mean |miss| (mA) latch-on / latch-off at the held-back 5 s and 20 s ramps")
    for path in sorted(args.data.glob("*_rates_s*")):
        row, line_fit = misses(path, powers)
        print(
            f"{path.name:32s} "
            + "  ".join(f"p={p}: {on:5.1f} / {off:5.1f}" for p, (on, off) in row.items())
            + "   miss vs line pressure: "
            + "  ".join(f"{k} r {c:+.2f} ({s:+.0f} mA/bar)" for k, (c, s) in line_fit.items()),
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
