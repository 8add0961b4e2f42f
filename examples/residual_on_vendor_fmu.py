"""A residual model on top of a vendor FMU (e.g. exported from Amesim) as the physics.

The FMU is stepped through FMPy on each experiment's time grid; the SVC-partitioned GP learns
what it misses on the fast + slow ramps; physics alone and physics + residual are scored on
the unseen medium ramp.

Usage::

    python examples/residual_on_vendor_fmu.py DATA VENDOR.fmu [--input-map FMU_IN=signal,...]
"""

from __future__ import annotations

import argparse

import numpy as np

from clutchlab.data import dither_period_mean, dither_period_samples, load_dataset
from clutchlab.physics.fmu import FmuPhysics
from clutchlab.residual_ml import HybridModel


def rmse(trace, pressure) -> float:
    n = dither_period_samples(trace)
    e = dither_period_mean(pressure, n) - dither_period_mean(trace.get("clutch_pressure_bar"), n)
    return float(np.sqrt(np.mean(e**2)))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", help="dataset folder")
    ap.add_argument("fmu", help="the vendor's FMI 2.0 co-simulation FMU")
    ap.add_argument("--input-map", default="", help="FMU input = canonical signal, comma separated")
    args = ap.parse_args()

    pairs = [p.split("=", 1) for p in args.input_map.split(",") if p]
    physics = FmuPhysics(args.fmu, input_map={k.strip(): v.strip() for k, v in pairs} or None)
    dataset = load_dataset(args.data)
    train = dataset.select(ramps=["fast", "slow"])
    # form="auto" (the default): residual model on the FMU, standalone ML, or the FMU alone,
    # whichever predicts best in leave-one-experiment-out on the training experiments.
    hybrid = HybridModel(physics=physics).fit(list(train))
    scores = ", ".join(f"{k} {v:.4f}" for k, v in hybrid.form_scores_.items())
    print(f"hybrid form: {hybrid.form_} (leave-one-experiment-out RMSE, bar: {scores})")
    print(f"{'medium experiment':24s} {'FMU alone':>10s} {'FMU + residual':>15s}  (RMSE, bar)")
    for trace in dataset.select(ramps=["medium"]):
        print(
            f"{trace.name:24s} {rmse(trace, physics.predict(trace)):10.4f} "
            f"{rmse(trace, hybrid.predict(trace)):15.4f}"
        )


if __name__ == "__main__":
    main()
