"""How much of the oil temperature a map of the current and its direction explains.

Issue 17 asks that a residual which drifts with another signal (oil temperature, line
pressure) be named even when the base model misfits, by removing "what a flexible map of
the current and its direction explains" before the signatures are computed. That only
works if the other signal is not itself a function of the current and its direction on
the training data. In the oil-drift case of ``studies/discover_zoo.py`` the oil warms from
40 to 85 °C through *every* run, so the temperature follows the position in the ramp
protocol, which the current and its direction also give.

For each dataset folder given, this prints the share of the training experiments' oil
temperature variance (dither-period means at the discovery's residual samples) that
binned means over (current, direction of travel) explain, and the standard deviation of
what is left. Nothing is chosen here.

Usage: ``python studies/oil_alias.py DIR [DIR ...] [--bins 12,24,48]``
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


def explained(path: Path, bins: list[int]) -> dict[int, tuple[float, float]]:
    """R² and residual std (°C) of the oil temperature on (current, direction) bins."""
    from clutchlab.data import load_dataset
    from clutchlab.validation.discover.residuals import _signals_at

    cur, sign, temp = [], [], []
    for t in load_dataset(path):
        if t.ramp not in ("fast", "slow"):
            continue
        rows = np.arange(0, len(t.time_s), 10)
        s = _signals_at(t, rows, np.asarray(t.get("clutch_pressure_bar"), dtype=float))
        cur.append(s["current_mA"])
        sign.append(s["didt_sign"])
        temp.append(s["oil_temp_C"])
    cur, sign, temp = (np.concatenate(v) for v in (cur, sign, temp))
    out = {}
    for nb in bins:
        q = np.unique(np.quantile(cur, np.linspace(0, 1, nb + 1)))
        cell = np.clip(np.searchsorted(q, cur, side="right") - 1, 0, len(q) - 2) * 3
        cell = cell + sign.astype(int) + 1
        fit = np.zeros_like(temp)
        for g in np.unique(cell):
            fit[cell == g] = temp[cell == g].mean()
        var = float(np.var(temp))
        out[nb] = (
            1.0 - float(np.var(temp - fit)) / var if var > 0 else 0.0,
            float(np.std(temp - fit)),
        )
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", type=Path, nargs="+", help="dataset folders")
    ap.add_argument("--bins", default="12,24,48", help="current bins per direction")
    args = ap.parse_args(argv)
    bins = [int(b) for b in args.bins.split(",")]
    for path in args.data:
        row = explained(path, bins)
        print(
            f"{path.name:28s} "
            + "  ".join(
                f"{nb} bins: R² {r2:.3f}, left {sd:.2f} °C" for nb, (r2, sd) in row.items()
            ),
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
