"""Evaluate a folder of test-stand logs whose channels have other names and units.

The logs are read through a channel map (TOML: canonical signal = source channel + unit),
every variant is trained on the fast + slow ramps and scored on the unseen medium ramp, and
the physics-vs-ML report is written.

Usage::

    python examples/evaluate_logs_with_channel_map.py LOGS MAP.toml --out REPORT
        [--variants physics_default,gp_base,gp_didt,paper_svc_gp]
"""

from __future__ import annotations

import argparse

from clutchlab.data import load_dataset
from clutchlab.validation import evaluate, write_report


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", help="dataset folder (manifest.json + logs)")
    ap.add_argument("map", help="channel map (TOML)")
    ap.add_argument("--out", required=True, help="report folder")
    ap.add_argument("--variants", default="physics_default,gp_base,gp_didt,paper_svc_gp")
    args = ap.parse_args()

    dataset = load_dataset(args.logs, channel_map=args.map)
    print(f"{len(dataset)} experiments, ramps {dataset.ramps}")
    ev = evaluate(dataset, args.variants.split(","), progress=False)
    files = write_report(ev, args.out)
    print(f"{'variant':16s} {'RMSE (bar)':>10s} {'fit %':>7s}")
    for name, m in files.doc["variants"].items():
        print(f"{name:16s} {m['rmse_bar']:10.4f} {m['fit_pct']:7.1f}")
    print(f"report: {files.html}")


if __name__ == "__main__":
    main()
