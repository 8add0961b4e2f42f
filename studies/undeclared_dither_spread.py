"""Logs that record only the measured current and the pressures, over the stand and the
four zoo plants: no command current, no dither amplitude or frequency column, none in the
manifest.

Session 43 made two changes for such logs: the dither frequency demodulated from the
measured current when the log is read is the period of every dither-period mean downstream
(DESIGN §3; before, those "means" were single samples), and the ramp rate of a measured
current is a least-squares slope over five periods (before, the noise of a two-sample slope
made a 27 mA/s ramp read faster than a 110 mA/s one). This study measures both over
structurally different circuits (``--seed``, 0 by default), three dither settings each: the
ramp rate per label against the protocol's, and ``gp_didt`` / ``paper_svc_gp`` trained on
fast + slow, scored on medium (scored only; nothing is chosen on it).

Usage: ``python studies/undeclared_dither_spread.py --make DIR`` writes the five datasets;
``PYTHONPATH=<code> python studies/undeclared_dither_spread.py --score DIR`` reads them with
that code and prints one JSON line per circuit.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from clutchlab.data import Dataset, Trace, load_dataset, save_dataset

PLANTS = ("stand", "quadratic_play", "saturating_lugre", "stribeck_supply", "preisach_accumulator")
DROPPED = ("dither_amp_mA", "dither_freq_Hz", "current_cmd_mA")


def make(root: Path, seed: int = 0) -> None:
    """The five datasets, as a logger of the measured current and pressures writes them."""
    from clutchlab.physics.stand import DEFAULT_SETTINGS, StandConfig, run_stand
    from clutchlab.physics.stand.plants import PlantConfig, run_plant

    settings = DEFAULT_SETTINGS[::4]
    for plant in PLANTS:
        if plant == "stand":
            data = run_stand(StandConfig(settings=settings, seed=seed), progress=False).dataset
        else:
            data = run_plant(PlantConfig(plant=plant, settings=settings, seed=seed), progress=False)
            data = data.dataset
        out = []
        for t in data:
            signals = {k: v for k, v in t.signals.items() if k not in DROPPED}
            meta = {k: v for k, v in t.meta.items() if k != "dither_freq_Hz"}
            out.append(Trace(t.name, signals, meta))
        save_dataset(Dataset(out), root / plant)


def score(root: Path) -> None:
    """Ramp rates and the two ML variants' medium-ramp RMSE per circuit, with this code."""
    from clutchlab.data import ramp_rate_mA_s
    from clutchlab.validation import evaluate

    for plant in PLANTS:
        t0 = time.perf_counter()
        data = load_dataset(root / plant)
        rates: dict[str, list[float]] = {}
        for t in data:
            rates.setdefault(t.ramp, []).append(ramp_rate_mA_s(t))
        ev = evaluate(data, ["gp_didt", "paper_svc_gp"], progress=False, classifiers=False,
                      bands=False)  # fmt: skip
        row = {"plant": plant}
        row |= {f"rate_{k}": [round(min(v), 1), round(max(v), 1)] for k, v in rates.items()}
        row |= {v: round(s.metrics["rmse_bar"], 4) for v, s in ev.scores.items()}
        row["wall_s"] = round(time.perf_counter() - t0, 1)
        print(json.dumps(row), flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--make", type=Path, help="write the five datasets into this folder")
    ap.add_argument("--score", type=Path, help="score the datasets in this folder")
    ap.add_argument("--seed", type=int, default=0, help="seed of the datasets --make writes")
    args = ap.parse_args()
    print(
        "rule (written before the runs): the new code must order every circuit's ramps "
        "fast > medium > slow by their measured rate with each rate within 25 % of the "
        "protocol's (fast 440, medium 110, slow 27.5 mA/s); the ML scores are reported as a "
        "spread over the five circuits, nothing is chosen on them.",
        flush=True,
    )
    if args.make:
        make(args.make, args.seed)
    if args.score:
        score(args.score)


if __name__ == "__main__":
    main()
