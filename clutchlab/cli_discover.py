"""``clutchlab discover``: close the loop — residual → named missing effect → refit → report."""

from __future__ import annotations

import argparse
import shlex
import sys

from .cli_types import add_map_argument, positive_float, print_dither_notes

__all__ = ["REPORT_FILES", "register"]

#: The fixed files of a discovery report (the iteration figures beside them vary); a
#: user's file of one of these names in --out is refused before any work.
REPORT_FILES = ("report.html", "report.md", "discovery.json")


def _csv(text: str | None) -> tuple[str, ...]:
    return tuple(s.strip() for s in (text or "").split(",") if s.strip())


def _split_labels(dataset, train: str | None, test: str | None):
    """The training and test ramp labels of ``--train`` / ``--test``, checked on ``dataset``.

    Every label given must be one of the dataset's ramps (a typo would otherwise drop its
    experiments silently). Without ``--test`` the test ramp is ``medium`` when the dataset
    has one and it is not trained on, else none (the report then scores the training
    experiments only).

    Parameters
    ----------
    dataset : Dataset
        The experiments.
    train, test : str or None
        The comma-separated labels as given (None: the default).

    Returns
    -------
    tuple of tuple of str
        Training labels, test labels.

    Raises
    ------
    DataError
        A label the dataset does not have (the message lists the known ones).
    """
    train_ramps = _csv(train) or ("fast", "slow")
    if test is None:
        medium = "medium" in dataset.ramps and "medium" not in train_ramps
        test_ramps = ("medium",) if medium else ()
    else:
        test_ramps = _csv(test) or ("medium",)
    dataset.select(ramps=train_ramps + test_ramps)  # raises on an unknown label
    return train_ramps, test_ramps


def _cmd_discover(args: argparse.Namespace) -> int:
    from .data import load_dataset
    from .physics import CircuitModel
    from .physics.fit import FitSettings
    from .validation.discover import DiscoverySettings, discover, write_report

    dataset = load_dataset(args.dataset, channel_map=args.map)
    print_dither_notes(dataset)
    train_ramps, test_ramps = _split_labels(dataset, args.train, args.test)
    model = CircuitModel().with_effects(*_csv(args.effects))
    fit = FitSettings(
        free=_csv(args.free) or None,
        train_ramps=train_ramps,
        progress=False,
        time_limit_s=args.time_limit,
        max_iter=args.max_iter,
        staged_start=False,  # as DiscoverySettings' default fit (see there)
        **({} if args.substeps is None else {"substeps": args.substeps}),
    )
    settings = DiscoverySettings(
        fit=fit,
        test_ramps=test_ramps,
        # each once: a repeated name would be scored twice and tighten the per-candidate
        # significance level (alpha / number of candidates)
        candidates=tuple(dict.fromkeys(_csv(args.candidates))) or None,
        max_effects=args.max_effects,
        alpha=args.alpha,
        alternatives=not args.no_alternatives,
        time_limit_s=args.budget,
        progress=not args.quiet,
    )
    baseline = None
    if args.physics_model:
        from .physics.fit import FitResult

        baseline = FitResult.from_json(args.physics_model)
    result = discover(dataset, model, settings, baseline=baseline)
    command = "clutchlab " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    report = write_report(result, args.out, command=command)
    print(result.table())
    print()
    print(result.summary)
    if result.time_limited:
        print(result.stop_note())
    if result.unexplained:
        print(result.next_steps())
    print(f"report: {report}")
    if args.json:
        from .cli import write_json_output

        write_json_output(args.json, result.to_json())
    return 0


def register(sub) -> None:
    """Add the ``discover`` subcommand to the ``clutchlab`` parser."""
    p = sub.add_parser(
        "discover",
        help="find the effects the physics model lacks from its residual, add them, report",
    )
    p.add_argument("dataset", help="dataset folder (manifest.json + experiments)")
    add_map_argument(p)
    p.add_argument("--out", required=True, help="report folder (report.html, figures, JSON)")
    p.add_argument("--json", help="also write the discovery result (JSON) here")
    p.add_argument("--max-effects", type=int, default=3, help="add at most N effects (3)")
    p.add_argument(
        "--effects", default="", help="effects already declared in the model, comma separated"
    )
    p.add_argument(
        "--free",
        default="",
        help="free parameters of the baseline fit (default: the standard set plus the "
        "declared effects' fit parameters); each added effect frees its own",
    )
    p.add_argument(
        "--candidates", default="", help="candidate effects (default: the whole library)"
    )
    p.add_argument("--train", default="fast,slow", help="training ramp labels (fast,slow)")
    p.add_argument(
        "--test",
        help="test ramp labels, only scored (default medium, when the dataset has that ramp "
        "and --train does not name it)",
    )
    p.add_argument(
        "--alpha", type=float, default=0.01, help="family-wise significance level (0.01)"
    )
    p.add_argument("--max-iter", type=int, default=50, help="solver iterations per fit (50)")
    p.add_argument(
        "--time-limit",
        type=positive_float,
        default=900.0,
        help="wall-time limit of each fit (s; default 900); --budget bounds the whole discovery",
    )
    p.add_argument(
        "--budget",
        type=positive_float,
        metavar="S",
        help="wall-time budget of the whole discovery (s; default none): no refit starts "
        "after it, a refit it stops is not judged, and the discovery ends with the model it "
        "had and a warning, claiming nothing it did not confirm in full",
    )
    p.add_argument(
        "--substeps",
        type=int,
        help="ROS2 integration steps per sample in every fit and score (default 2); more "
        "when the summary says the model's integration diverged (slower in proportion)",
    )
    p.add_argument(
        "--physics-model",
        metavar="FIT.json",
        help="a fit from `clutchlab fit-physics` on this dataset's training ramps: the "
        "discovery starts from it instead of fitting the base model again; refused if it was "
        "fitted on other experiments or lacks --effects",
    )
    p.add_argument(
        "--no-alternatives",
        action="store_true",
        help="claim an effect without asking that it predict the left-out experiments "
        "better than each flexible component law of at most its size (default: asked)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress display")
    p.set_defaults(func=_cmd_discover, report_out=True, report_files=REPORT_FILES)
