"""Design study before hardware exists: sweep a spec, rank the designs by a metric.

Runs every design point of a sweep spec (TOML, see ``sweep_vfs_design.toml``) through the
physics model and prints the designs with the smallest fast-ramp hysteresis width (in size:
the width is negative when the rising branch lies below the falling one) and their latch
currents.

Usage::

    python examples/design_sweep.py SPEC.toml --out results.parquet [--workers 2]
"""

from __future__ import annotations

import argparse

from clutchlab.physics.design import load_spec, run_sweep


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("spec", help="sweep spec (TOML)")
    ap.add_argument("--out", required=True, help="results file (.parquet)")
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument(
        "--metric", default="hysteresis_fast_bar", help="rank by the size of this metric column"
    )
    args = ap.parse_args()

    spec = load_spec(args.spec)
    result = run_sweep(spec, args.out, workers=args.workers, progress=False)
    table = result.table
    print(result.summary())
    variables = [v.name for v in spec.variables]
    # Smallest in size: a hysteresis width of -3 bar is wider than one of -0.9 bar.
    ok = table[table["status"] == "ok"]
    best = ok.sort_values(args.metric, key=lambda x: x.abs()).head(5)
    print(best[[*variables, args.metric, "latch_on_mA", "latch_off_mA"]].to_string(index=False))


if __name__ == "__main__":  # worker processes start fresh: scripts need the main guard
    main()
