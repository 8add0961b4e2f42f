"""Fit the physics model to the training ramps, export it as an FMU, check the FMU.

The fitted model is saved as JSON (``model.json``), exported as an FMI 2.0 co-simulation FMU
(``clutch.fmu``), imported back through FMPy and compared with the in-process model on the
unseen medium ramp.

Usage::

    python examples/fit_and_export_fmu.py DATA --out FOLDER [--max-iter 30] [--time-limit 120]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from clutchlab.data import load_dataset
from clutchlab.physics.fit import FitSettings, PhysicsFitter
from clutchlab.physics.fmu import FmuPhysics, export_physics_fmu


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", help="dataset folder")
    ap.add_argument("--out", required=True, help="folder for model.json and clutch.fmu")
    ap.add_argument("--max-iter", type=int, default=30, help="fit iterations")
    ap.add_argument("--time-limit", type=float, default=120.0, help="fit wall limit, s")
    args = ap.parse_args()

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    dataset = load_dataset(args.data)
    settings = FitSettings(max_iter=args.max_iter, time_limit_s=args.time_limit, progress=False)
    fitter = PhysicsFitter(settings=settings).fit(dataset)
    print(fitter.result_.table())
    fitter.save(out / "model.json")
    fmu = export_physics_fmu(out / "model.json", out / "clutch.fmu", drive="measured")
    print(f"FMU: {fmu}")

    trace = dataset.select(ramps=["medium"])[0]
    in_process = fitter.predict(trace)
    from_fmu = FmuPhysics(fmu).predict(trace)
    diff = float(np.max(np.abs(from_fmu - in_process)))
    print(f"{trace.name}: FMU vs in-process max |difference| {diff:.2e} bar")


if __name__ == "__main__":
    main()
