"""``clutchlab select-structure``: choose the fit model's flexible laws inside the training set."""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from .cli_types import add_map_argument, positive_float, print_dither_notes

__all__ = ["register"]


def _csv(text: str | None) -> tuple[str, ...]:
    return tuple(s.strip() for s in (text or "").split(",") if s.strip())


def _unfinished_candidates(selection) -> list[str]:
    """The candidates of a structure selection whose fit stopped before converging.

    A flexible candidate that kept its start (the plain optimum, because its iterate was
    worse on the training set) is a finished decision, not listed.

    Parameters
    ----------
    selection : StructureSelection
        From :class:`~clutchlab.physics.fit.StructureSelector`.

    Returns
    -------
    list of str
        ``"name (solver status)"`` per unfinished candidate, in the order fitted.
    """
    return [
        f"{c.name} ({c.status})"
        for c in selection.candidates
        if not c.converged and "kept its start" not in c.status
    ]


def _cmd_select_structure(args: argparse.Namespace) -> int:
    from .data import load_dataset
    from .physics.fit import FitSettings, StructureSelector

    dataset = load_dataset(args.dataset, channel_map=args.map)
    print_dither_notes(dataset)
    train_ramps = _csv(args.train) or ("fast", "slow")
    dataset.select(ramps=train_ramps)  # an unknown label is an error, not a dropped ramp
    settings = FitSettings(
        train_ramps=train_ramps,
        progress=not args.quiet,
        time_limit_s=args.time_limit,
    )
    candidates = tuple(dict.fromkeys(_csv(args.candidates))) or None  # each one fitted once
    selector = StructureSelector(candidates, settings, base_effects=_csv(args.effects)).fit(dataset)
    sel = selector.selection_
    print(sel.table())
    stopped = _unfinished_candidates(sel)
    if stopped:
        print(
            f"clutchlab select-structure: warning: {len(stopped)} of {len(sel.candidates)} "
            f"candidate fits stopped before converging ({'; '.join(stopped)}): each is scored "
            "at its best iterate (its start when no iteration finished), so the choice may "
            "differ with a longer --time-limit",
            file=sys.stderr,
        )
    if args.out:
        out = Path(args.out)
        sel.best_result().to_json(out)
        print(f"fitted model of structure {sel.chosen!r} written to {out}")
    if args.json:
        sel.to_json(args.json)
        print(f"structure choice written to {args.json}")
    print("score it with: " + _evaluate_hint(args, sel.effects, train_ramps))
    return 0


def _evaluate_hint(args: argparse.Namespace, effects: list[str], train: tuple[str, ...]) -> str:
    """The ``clutchlab evaluate`` command that scores the chosen structure on the test ramp:
    reusing the fit written to ``--out`` when there is one, with the same training ramps."""
    words = ["clutchlab", "evaluate", str(args.dataset)]
    if args.out:
        words += ["--physics-model", str(args.out)]
    if effects:
        words += ["--effects", ",".join(effects)]
    if train != ("fast", "slow"):
        words += ["--train", ",".join(train)]
    return " ".join(shlex.quote(w) for w in words) + " --out REPORT"


def register(sub) -> None:
    """Add the ``select-structure`` subcommand to the ``clutchlab`` parser."""
    p = sub.add_parser(
        "select-structure",
        help="fit candidate structures (flexible laws) and choose one by BIC on training data",
        description=(
            "Fit each candidate structure (the base circuit plus flexible component laws) "
            "to the training experiments and choose the one with the lowest BIC of the "
            "training period-mean residuals (AR(1) effective sample size). The test ramp "
            "is never read."
        ),
    )
    p.add_argument("dataset", help="dataset folder (manifest.json + experiments)")
    add_map_argument(p)
    p.add_argument(
        "--candidates",
        default="",
        help=(
            "structures, comma separated: plain, force, play, latch, vfs, flex "
            "(default plain,force,play,latch)"
        ),
    )
    p.add_argument("--effects", default="", help="library effects on in every candidate")
    p.add_argument("--train", default="fast,slow", help="training ramp labels (fast,slow)")
    p.add_argument(
        "--time-limit", type=positive_float, default=900.0, help="wall limit per candidate fit (s)"
    )
    p.add_argument("--out", help="write the chosen structure's fitted model (JSON) here")
    p.add_argument("--json", help="write the choice with every candidate's training score here")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_select_structure, file_out="json", out_writes="fit")
