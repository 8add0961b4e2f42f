"""Benchmark: effect discovery on stand data with one undeclared effect (issue 7, must-show 1).

For each case of ``MUST_SHOW_CASES`` (``clutchlab.validation.discover.scenarios``): run the
short discovery stand with that effect switched on, discover with the base model (at most
one effect), and print the effect named first, the score statistic and explained share of
the winner and the runner-up, the RMSE of the dither-period-mean pressure before and after
on the training ramps and on the unseen medium ramp, and the wall time. The same cases
are asserted by ``tests/test_discover_effects.py`` (``pytest -m slow``).

Usage: ``python benchmarks/bench_discover.py [--effects a,b] [--default-strength]
[--set NAME=VALUE ...] [--n-settings N] [--json OUT]``

``--speed STAND [--repeat N]`` (issue 17, must-show 1): on the default stand (generated into
the folder ``STAND`` when it holds no dataset), the wall time of ``clutchlab fit-physics`` and
of ``clutchlab discover`` (its own baseline fit included), each as a fresh console-script
process, alternated N times; prints every run, the medians and the ratio
discovery / fit-physics of the medians, with the effects each discovery added.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from clutchlab.physics.fit import FitSettings
from clutchlab.validation.discover import DiscoverySettings
from clutchlab.validation.discover.scenarios import MUST_SHOW_CASES, run_must_show


def run_case(effect: str, n_settings: int, overrides: dict, max_iter: int) -> dict:
    """Measured row of one case (see ``scenarios.must_show_row``)."""
    settings = DiscoverySettings(fit=FitSettings(progress=False, max_iter=max_iter), progress=False)
    _, row = run_must_show(effect, overrides, n_settings=n_settings, settings=settings)
    row["n_settings"] = n_settings
    return row


def _timed(argv: list[str]) -> float:
    t0 = time.perf_counter()
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def speed(stand: str, repeat: int, keep: str | None = None) -> None:
    """Discovery vs one physics fit on the same data, measured in one run; the fit and
    discovery JSONs are kept in ``keep`` when given."""
    exe = [sys.executable, "-m", "clutchlab"]
    folder = Path(stand)
    if not (folder / "manifest.json").exists():
        subprocess.run([*exe, "stand", "--out", str(folder)], check=True)
    fits, discs = [], []
    if keep:
        Path(keep).mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=keep) as scratch:
        tmp = keep or scratch
        for k in range(repeat):
            fits.append(_timed([*exe, "fit-physics", stand, "--out", f"{tmp}/fit{k}.json"]))
            js = f"{tmp}/disc{k}.json"
            discs.append(
                _timed([*exe, "discover", stand, "--out", f"{tmp}/d{k}", "--json", js, "--quiet"])
            )
            doc = json.loads(Path(js).read_text(encoding="utf-8"))
            fit = json.loads(Path(f"{tmp}/fit{k}.json").read_text(encoding="utf-8"))
            print(
                f"run {k + 1}: fit-physics {fits[-1]:.1f} s ({fit['status']}); discover "
                f"{discs[-1]:.1f} s, added {doc['added'] or 'nothing'}, iterations "
                + ", ".join(f"{it['wall_s']:.0f} s" for it in doc["iterations"])
                + f"; summary: {doc['summary']}",
                flush=True,
            )
    f, d = statistics.median(fits), statistics.median(discs)
    print(f"median over {repeat}: fit-physics {f:.1f} s, discover {d:.1f} s, ratio {d / f:.2f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--speed", metavar="STAND", help="discovery vs fit-physics on this stand")
    ap.add_argument("--repeat", type=int, default=3, help="runs of each (--speed)")
    ap.add_argument("--keep", metavar="DIR", help="keep the JSONs and reports here (--speed)")
    ap.add_argument("--effects", default="", help="comma-separated subset of the cases")
    ap.add_argument(
        "--default-strength",
        action="store_true",
        help="the stand's default effect strengths instead of the cases' overrides",
    )
    ap.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="truth value (engineering units) instead of the cases' overrides; repeatable",
    )
    ap.add_argument("--n-settings", type=int, help="dither settings (1 or 3) for every case")
    ap.add_argument("--max-iter", type=int, default=50, help="solver iterations per fit")
    ap.add_argument("--json", help="write the rows here")
    args = ap.parse_args()
    if args.speed:
        print(
            f"machine: {platform.machine()}, {os.cpu_count()} cores, "
            f"Python {platform.python_version()}"
        )
        speed(args.speed, args.repeat, args.keep)
        return
    wanted = [e for e in args.effects.split(",") if e] or list(MUST_SHOW_CASES)
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    )
    print(
        "| effect | truth | named first | winner (statistic / share) | runner-up "
        "(statistic / share) | train RMSE before → after (bar) | medium RMSE before → after "
        "(bar) | medium drop | wall (s) |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    rows = []
    for effect in wanted:
        n_settings, overrides = MUST_SHOW_CASES.get(effect, (1, {}))
        if args.default_strength:
            overrides = {}
        if args.set:
            overrides = {k: float(v) for k, v in (s.split("=", 1) for s in args.set)}
        n_settings = args.n_settings or n_settings
        row = run_case(effect, n_settings, overrides, args.max_iter)
        rows.append(row)
        if args.json:
            with open(args.json, "w", encoding="utf-8") as f:
                json.dump(rows, f, indent=2)
        truth = ", ".join(f"{k} = {v:g}" for k, v in overrides.items()) or "default"
        w, r = row["winner"], row["runner_up"]
        print(
            f"| {effect} | {truth} | {row['named_first'] or '—'} | "
            f"{w[0]} {w[1]:.1f} / {w[2]:.2f} | "
            + (f"{r[0]} {r[1]:.1f} / {r[2]:.2f}" if r else "—")
            + f" | {row['train_rmse_bar'][0]:.4f} → {row['train_rmse_bar'][1]:.4f} | "
            f"{row['test_rmse_bar'][0]:.4f} → {row['test_rmse_bar'][1]:.4f} | "
            f"{row['test_drop_pct']:.0f} % | {row['wall_s']:.0f} |",
            flush=True,
        )


if __name__ == "__main__":
    main()
