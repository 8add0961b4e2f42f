"""The paper pipeline on logs without dither, over the stand and the four zoo plants.

Session 42 changed what the features do when a log has no dither at all (no dither columns,
no manifest frequency, none found in the measured current): the dI/dt window counts in
periods of 50 Hz (``clutchlab.data.demodulate.NO_DITHER_DIDT_HZ``) instead of 5 samples, and
a line below 1 mA in the current is no dither. This study measures the spread of that change
over structurally different circuits: each plant (seed 0) runs the three ramps at three
settings whose dither amplitude is zero; the logs keep the measured current only (no command,
no dither columns); ``gp_didt`` and ``paper_svc_gp`` are trained on fast + slow and scored on
medium (scored only, nothing chosen on it).

Usage: ``PYTHONPATH=<code> python studies/nodither_spread.py`` — run once per code state to
compare; one JSON line per circuit.
"""

from __future__ import annotations

import json
import time

import numpy as np

from clutchlab.data import Dataset, Trace
from clutchlab.physics.stand import DitherSetting, StandConfig, run_stand, scenarios
from clutchlab.physics.stand.plants import PlantConfig, run_plant
from clutchlab.validation import evaluate

PLANTS = ("stand", "quadratic_play", "saturating_lugre", "stribeck_supply", "preisach_accumulator")
DROPPED = ("dither_amp_mA", "dither_freq_Hz", "current_cmd_mA")


def _measured_only(dataset: Dataset) -> Dataset:
    """The logs as a stand without dither channels would write them."""
    out = []
    for t in dataset:
        signals = {k: v for k, v in t.signals.items() if k not in DROPPED}
        meta = {k: v for k, v in t.meta.items() if k != "dither_freq_Hz"}
        out.append(Trace(t.name, signals, meta))
    return Dataset(out)


def main() -> None:
    scenarios.DITHER_SHAPES["Z"] = lambda i: 0.0 * np.asarray(i, dtype=float)  # no dither
    settings = tuple(DitherSetting(f, "Z") for f in (30.0, 50.0, 70.0))
    for plant in PLANTS:
        t0 = time.perf_counter()
        if plant == "stand":
            data = run_stand(StandConfig(settings=settings, seed=0), progress=False).dataset
        else:
            config = PlantConfig(plant=plant, settings=settings, seed=0)
            data = run_plant(config, progress=False).dataset
        ev = evaluate(
            _measured_only(data),
            ["gp_didt", "paper_svc_gp"],
            progress=False,
            classifiers=False,
            bands=False,
        )
        row = {"plant": plant}
        row |= {v: round(s.metrics["rmse_bar"], 4) for v, s in ev.scores.items()}
        row |= {"failed": dict(ev.failed), "s": round(time.perf_counter() - t0, 1)}
        print(json.dumps(row), flush=True)


if __name__ == "__main__":
    main()
