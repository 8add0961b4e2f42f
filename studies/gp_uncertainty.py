"""The single GP's predictive uncertainty (``gp_didt``): calibrate ``κ_p`` of its rate bridge on
held-back training-side ramp rates, then report its ±2σ coverage on the medium ramp (issue 20,
must-show 4).

``GPWithDerivative`` (one GP over both latch states, with dI/dt) widens its predictive std by
(a) a residual-variance floor learned from its leave-one-experiment-out residuals
(``residual_variance="loeo"``, :mod:`clutchlab.residual_ml.residual_variance`) and (b) the
rate bridge (``rate_uncertainty="bridge"``): ``κ_p`` times the GP's change between the two
bracketing trained ramp rates, which for one GP also moves the latch switch. ``κ_p`` cannot
be learnt from two training rates, so it is calibrated here on datasets with extra
*training-side* ramps (fast 2.5 s, 5 s, 20 s, slow 40 s; those of ``studies/latch_event.py``):
train fast + slow, score the 5 s and 20 s ramps. The 10 s medium ramp is not in them.

Usage:

* ``python studies/gp_uncertainty.py --data DIR --out F.json [--seeds 0,1,2] [--plants ...]
  [--kappas 0,0.5,1,1.5,2,3]`` calibrates ``κ_p`` (the rule is printed first);
* ``python studies/gp_uncertainty.py --medium DIR --data DIR --out F.json [--variant gp_base]``
  scores the defaults of ``gp_didt`` (or ``gp_base``, which has the floor but no dI/dt, so
  no rate term) against the GP's own std on the standard datasets' medium ramp (train fast
  + slow, the 9 medium experiments scored; nothing chosen there).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

# The held-back-rate and standard datasets of the latch studies (same plants, ramps, seeds):
# one writer each, so the studies read the same data. The script's folder is on sys.path.
from latch_event import PLANTS, each_dataset, rates_dataset
from latch_timing import REGIONS, SHORT, standard_dataset

RULE = """\
Decision rule (fixed before the run; the 10 s medium ramp is not used):
  pressure_rate_scale of the single GPs (kappa_p, GP_PRESSURE_RATE_SCALE) = the smallest value
  of the grid whose +-2 sigma coverage in the latch window (within 0.15 s of a measured snap
  or release), pooled over the held-back 5 s and 20 s ramps, is >= 90 % in the worst seed on
  the most circuits (GPWithDerivative with residual_variance="loeo").
Also printed (not decided on): the regulated / latched coverage and the mean band width
(2 sigma, bar) per region; "gp" = the GP's own std (no floor, no bridge)."""

#: Parameter sets of ``--medium``: the GP's own std, and the defaults.
MEDIUM_KINDS = {"gp": {"rate_uncertainty": "none", "residual_variance": "none"}, "default": {}}


def _coverage(refs, means, stds, settings) -> dict:
    """±2σ coverage per region and the mean 2σ band per region, pooled over experiments."""
    from clutchlab.validation import coverage_regions, interval_coverage

    counts = {r: [0, 0] for r in REGIONS}
    bands = {r: [] for r in REGIONS}
    for ref, mean, std in zip(refs, means, stds, strict=True):
        pm = ref.period_mean
        line, meas = pm(ref.line_bar), ref.measured_mean_bar
        got = interval_coverage(ref.time_s, line, meas, pm(mean), pm(std), settings)
        masks = coverage_regions(ref.time_s, line, meas, settings)
        for r, (i, n) in got.items():
            counts[r][0] += i
            counts[r][1] += n
            bands[r].append(2 * pm(std)[masks[r]])
    out = {r: i / n if n else float("nan") for r, (i, n) in counts.items()}
    out.update({f"band_{SHORT[r]}_bar": float(np.mean(np.concatenate(bands[r]))) for r in REGIONS})
    return out


def coverage(path: Path, kappas: list[float]) -> dict:
    """Coverage per region for each ``κ_p`` (and the GP's own std), on the 5 s + 20 s ramps."""
    from clutchlab.data import load_dataset
    from clutchlab.residual_ml import GPWithDerivative
    from clutchlab.validation import AnalysisSettings, ExperimentReference

    ds = load_dataset(path)
    train = [t for t in ds if t.ramp in ("fast", "slow")]
    test = [t for t in ds if t.ramp in ("r5", "r20")]
    model = GPWithDerivative().fit(train)
    s = AnalysisSettings()
    refs = [ExperimentReference.of(t, s) for t in test]
    # One fit gives every row: the GP's own std is this fit without its floor (a fit with
    # residual_variance="none" has the same GP and no floor), and the bridge's variance is
    # κ_p² times that at κ_p = 1.
    floor = model.variance_floor_
    parts = {}
    for name, kept, params in (
        ("gp", None, {"rate_uncertainty": "none"}),
        ("floor", floor, {"rate_uncertainty": "bridge", "pressure_rate_scale": 0.0}),
        ("unit", floor, {"rate_uncertainty": "bridge", "pressure_rate_scale": 1.0}),
    ):
        model.variance_floor_ = kept
        model.set_params(**params)
        parts[name] = [model.predict(t, return_std=True) for t in test]
    means = [m for m, _ in parts["floor"]]
    out = {"by_kappa": {"gp": _coverage(refs, means, [sd for _, sd in parts["gp"]], s)}}
    for k in kappas:
        stds = [
            np.sqrt(f**2 + k**2 * np.maximum(u**2 - f**2, 0.0))
            for (_, f), (_, u) in zip(parts["floor"], parts["unit"], strict=True)
        ]
        out["by_kappa"][str(k)] = _coverage(refs, means, stds, s)
    return out


def medium_coverage(path: Path, variant: str = "gp_didt") -> dict:
    """A single GP's ±2σ coverage and RMSE on the medium ramp: the GP's std, the defaults."""
    from clutchlab.data import load_dataset
    from clutchlab.residual_ml import VARIANTS
    from clutchlab.validation import Protocol

    protocol = Protocol(load_dataset(path), train=("fast", "slow"), test=("medium",))
    out = {}
    for kind, params in MEDIUM_KINDS.items():
        model, fit_s = protocol.fit(VARIANTS[variant](**params))
        score = protocol.score(kind, model, fit_s=fit_s)
        out[kind] = {
            **score.details["coverage_2sigma"],
            "rmse_bar": score.metrics["rmse_bar"],
            "fit_s": fit_s,
        }
    return out


def score_medium(args) -> int:
    """``--medium``: the defaults against the GP's own std on the medium ramp."""
    from clutchlab.residual_ml import GP_PRESSURE_RATE_SCALE

    print(
        f"Scoring {args.variant}'s defaults (residual_variance = 'loeo', rate_uncertainty = "
        f"'bridge', pressure_rate_scale = {GP_PRESSURE_RATE_SCALE}) against the GP's own std "
        "on the medium ramp: train fast + slow, score the 9 medium experiments; nothing is "
        "chosen here.",
        flush=True,
    )
    args.medium.mkdir(parents=True, exist_ok=True)
    rows = each_dataset(
        args,
        lambda p, s: standard_dataset(args.medium, p, s),
        lambda path: medium_coverage(path, args.variant),
        lambda r: (
            f"{r['plant']:22s} {r['seed']}  "
            + "   ".join(
                f"{k}: "
                + " ".join(f"{SHORT[g]} {v[g]:.3f}" for g in REGIONS)
                + f" rmse {v['rmse_bar']:.3f} fit {v['fit_s']:.0f} s"
                for k, v in r.items()
                if k in MEDIUM_KINDS
            )
        ),
    )
    print("\nper circuit, defaults: mean over seeds [worst] (the GP's own std: mean)")
    for plant in dict.fromkeys(r["plant"] for r in rows):
        mine = [r for r in rows if r["plant"] == plant]
        cells = []
        for g in REGIONS:
            d = [r["default"][g] for r in mine]
            own = np.mean([r["gp"][g] for r in mine])
            cells.append(f"{SHORT[g]} {np.mean(d):.3f} [{min(d):.3f}] ({own:.3f})")
        print(f"  {plant:22s} " + "  ".join(cells))
    return 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, required=True, help="dataset cache folder")
    ap.add_argument("--out", type=Path, required=True, help="JSON results")
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--plants", default=",".join(PLANTS))
    ap.add_argument("--kappas", default="0,0.5,1,1.5,2,3")
    ap.add_argument(
        "--medium",
        type=Path,
        help="score the defaults on the standard datasets in this folder (medium ramp)",
    )
    ap.add_argument(
        "--variant",
        choices=("gp_didt", "gp_base"),
        default="gp_didt",
        help="the single GP --medium scores (default gp_didt)",
    )
    args = ap.parse_args(argv)
    if args.medium is not None:
        return score_medium(args)
    kappas = [float(k) for k in args.kappas.split(",")]
    print(RULE, flush=True)
    args.data.mkdir(parents=True, exist_ok=True)
    rows = each_dataset(
        args,
        lambda p, s: rates_dataset(args.data, p, s),
        lambda path: coverage(path, kappas),
        lambda r: (
            f"{r['plant']:22s} {r['seed']}  window: "
            + "  ".join(f"k={k}: {v['latch_window']:.2f}" for k, v in r["by_kappa"].items())
        ),
    )
    print("\ncoverage per region in the worst seed, and the mean 2 sigma band (bar) per region")
    meets = {}
    for k in ("gp", *(str(k) for k in kappas)):
        print(f"kappa_p {k}")
        n = 0
        for plant in dict.fromkeys(r["plant"] for r in rows):
            mine = [r["by_kappa"][k] for r in rows if r["plant"] == plant]
            worst = {g: min(x[g] for x in mine) for g in REGIONS}
            band = {g: np.mean([x[f"band_{SHORT[g]}_bar"] for x in mine]) for g in REGIONS}
            n += worst["latch_window"] >= 0.90
            print(
                f"  {plant:22s} "
                + "  ".join(f"{SHORT[g]} {worst[g]:.3f} (band {band[g]:.2f})" for g in REGIONS)
            )
        if k != "gp":
            meets[k] = n
    best = max(meets.values())
    pick = next(k for k in meets if meets[k] == best)
    print(
        f"\ncircuits with worst-seed window coverage >= 90 % per kappa_p: {meets}\n"
        f"chosen pressure_rate_scale of the single GPs = {pick} (the smallest with the most, "
        f"{best} of {len(set(r['plant'] for r in rows))})"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
