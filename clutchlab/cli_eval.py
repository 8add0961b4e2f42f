"""``clutchlab evaluate`` and ``clutchlab demo``: the physics-vs-ML comparison report."""

from __future__ import annotations

import argparse
import shlex
import sys
from pathlib import Path

from .budgets import FIT_BUDGET_S
from .cli_types import add_map_argument, positive_float, print_dither_notes
from .report_files import REPORT_FILES

__all__ = ["REPORT_FILES", "command_line", "register", "run_demo_command"]

#: The fixed files of an evaluation report (figures/ beside them vary with the variants);
#: a user's file of one of these names in --out is refused before any work.


def _csv(text: str | None) -> tuple[str, ...]:
    return tuple(s.strip() for s in (text or "").split(",") if s.strip())


def command_line() -> str:
    """The command line of this process, as recorded in reports."""
    return "clutchlab " + " ".join(shlex.quote(a) for a in sys.argv[1:])


def _finish(files, failed: dict[str, str], json_path: str | None) -> int:
    from .validation import write_json
    from .validation.report import summary_lines

    if json_path:
        write_json(files.doc, json_path)
    for name, why in failed.items():
        what = (
            "the latch-classifier comparison"
            if name == "classifier_comparison"
            else f"variant {name}"
        )
        print(f"{what} failed: {why}", file=sys.stderr)
    for line in summary_lines(files.doc):
        print(line)
    saved = (files.doc.get("models") or {}).get("files") or {}
    if saved:
        print(
            f"models: {files.folder / 'models'} ({', '.join(saved)}; "
            "`clutchlab predict` and `clutchlab export-fmu` take them)"
        )
    print(f"report: {files.html}")
    return 1 if failed else 0


def _fmu_params(items: list[str] | None, fmu: str | None) -> dict[str, float]:
    """``--fmu-param NAME=VALUE`` options as a dict.

    Raises
    ------
    ModelError
        A malformed option (its text), or ``--fmu-param`` without ``--physics-fmu`` (it
        would be ignored): a usage error, exit status 2 like every other one, not the
        status 1 of a failed variant.
    """
    from .errors import ModelError

    out = {}
    for item in items or ():
        name, sep, value = item.partition("=")
        try:
            if not sep or not name.strip():
                raise ValueError
            out[name.strip()] = float(value)
        except ValueError:
            raise ModelError(f"--fmu-param {item!r}: expected NAME=VALUE with a number") from None
    if out and not fmu:
        raise ModelError(
            "--fmu-param sets a parameter of the --physics-fmu FMU, and no --physics-fmu was given"
        )
    return out


def _fmu_ports(
    items: list[str] | None, output: str | None, fmu: str | None
) -> tuple[dict[str, str], str | None]:
    """``--fmu-input FMU_INPUT=SIGNAL`` options as a dict, and ``--fmu-output``.

    Raises
    ------
    ModelError
        A malformed ``--fmu-input`` (its text), or either option without ``--physics-fmu``
        (it would be ignored): a usage error, exit status 2.
    """
    from .errors import ModelError

    out = {}
    for item in items or ():
        name, sep, signal = item.partition("=")
        if not sep or not name.strip() or not signal.strip():
            raise ModelError(
                f"--fmu-input {item!r}: expected FMU_INPUT=SIGNAL, e.g. I_cmd=current_cmd_mA"
            )
        out[name.strip()] = signal.strip()
    given = [o for o, v in (("--fmu-input", out), ("--fmu-output", output)) if v]
    if given and not fmu:
        raise ModelError(
            f"{' and '.join(given)} name(s) a port of the --physics-fmu FMU, and no "
            "--physics-fmu was given"
        )
    return out, output


def _cmd_evaluate(args: argparse.Namespace) -> int:
    from .data import load_dataset
    from .physics import CircuitModel
    from .physics.fit import FitSettings
    from .validation import evaluate, write_report

    fmu_params = _fmu_params(args.fmu_param, args.physics_fmu)  # fails before any work
    input_map, output = _fmu_ports(args.fmu_input, args.fmu_output, args.physics_fmu)
    dataset = load_dataset(args.dataset, channel_map=args.map)
    print_dither_notes(dataset)
    fmu = None
    if args.physics_fmu:
        from .physics.fmu import FmuPhysics

        fmu = FmuPhysics(
            args.physics_fmu,
            timeout_s=args.fmu_timeout,
            isolate=args.fmu_isolate,
            parameters=fmu_params,
            input_map=input_map or None,
            output=output,
        )
    kw = {"progress": not args.quiet, "time_limit_s": args.fit_time_limit}
    if args.fit_max_iter is not None:
        kw["max_iter"] = args.fit_max_iter
    options = {}
    physics_model = CircuitModel().with_effects(*_csv(args.effects))
    if args.physics_model:
        from .physics.fit import PhysicsFitter
        from .validation.variants import check_fit_effects

        fitted = PhysicsFitter.load(args.physics_model)
        check_fit_effects(fitted.result_, physics_model)  # before any variant is fitted
        options["physics_fitted"] = {"fitted": fitted}
    ev = evaluate(
        dataset,
        _csv(args.variants) or None,
        train=_csv(args.train),
        test=_csv(args.test),
        physics_model=physics_model,
        physics_settings=FitSettings(**kw),
        on_error="report",
        progress=not args.quiet,
        classifiers=False if args.no_classifiers else None,
        command=command_line(),
        physics_fmu=fmu,
        options=options,
    )
    files = write_report(ev, Path(args.out))
    return _finish(files, ev.failed, args.json)


def run_demo_command(args: argparse.Namespace) -> int:
    """The ``clutchlab demo`` subcommand (registered in :mod:`clutchlab.cli`)."""
    from .validation import run_demo

    result = run_demo(
        args.out,
        progress=not args.quiet,
        command=command_line(),
        variants=_csv(getattr(args, "variants", "")) or None,
        time_budget_s=None if args.no_budget else args.budget,
    )
    return _finish(result.files, result.failed, args.json)


def register(sub) -> None:
    """Add the ``evaluate`` subcommand to the ``clutchlab`` parser."""
    p = sub.add_parser(
        "evaluate",
        help="fit every variant on the training ramps, score it on the test ramp, write a report",
        description=(
            "Fit each variant on the training experiments (ramps --train), score it on the "
            "test experiments (ramps --test, never used for fitting), and write report.html, "
            "report.md, metrics.json, metrics.csv and figures/ into --out. Exit status 1 if "
            "a variant failed (the report lists it)."
        ),
    )
    p.add_argument("dataset", help="dataset folder (manifest.json + experiments)")
    p.add_argument("--out", required=True, help="report folder to write")
    p.add_argument(
        "--variants",
        default="",
        help="comma separated, e.g. physics_default,physics_fitted,paper_svc_gp "
        "(default: every available variant)",
    )
    p.add_argument("--train", default="fast,slow", help="training ramp labels (fast,slow)")
    p.add_argument("--test", default="medium", help="test ramp labels (medium)")
    add_map_argument(p)
    p.add_argument("--effects", default="", help="effects of the fitted physics model")
    p.add_argument(
        "--fit-time-limit",
        type=positive_float,
        default=FIT_BUDGET_S,
        help=f"physics fit wall limit, s ({FIT_BUDGET_S:g}, the fit budget; the best iterate by "
        "then is the "
        "model, marked not converged)",
    )
    p.add_argument("--fit-max-iter", type=int, default=None, help="physics fit iteration limit")
    p.add_argument(
        "--physics-model",
        metavar="FIT.json",
        help="a fit from `clutchlab fit-physics` on this dataset's training ramps: used as "
        "physics_fitted (and under hybrid) instead of fitting again; refused if it was "
        "fitted on other experiments or lacks --effects",
    )
    p.add_argument(
        "--no-classifiers",
        action="store_true",
        help="skip the latch-classifier comparison (run by default with an ML variant)",
    )
    p.add_argument(
        "--physics-fmu",
        metavar="FILE.fmu",
        help="an FMI 2.0 co-simulation FMU as the physics model (e.g. from Amesim or "
        "`clutchlab export-fmu`): scored as variant physics_fmu, and the physics under "
        "hybrid instead of the fitted in-process model",
    )
    p.add_argument(
        "--fmu-param",
        action="append",
        metavar="NAME=VALUE",
        help="set an FMU parameter before initialization (in the FMU's unit); repeat for "
        "more. Parameters left at the FMU's start value are listed in the report",
    )
    p.add_argument(
        "--fmu-input",
        action="append",
        metavar="FMU_INPUT=SIGNAL",
        help="feed the FMU input FMU_INPUT from the canonical signal SIGNAL (e.g. "
        "I_cmd=current_cmd_mA); repeat for more. Inputs named like a canonical signal are "
        "fed without it; the others keep their start values",
    )
    p.add_argument(
        "--fmu-output",
        metavar="NAME",
        help="the FMU's Real output with the clutch pressure (default clutch_pressure_bar, "
        "else its only Real output)",
    )
    p.add_argument(
        "--fmu-timeout",
        type=positive_float,
        default=600.0,
        help="wall-time limit of one experiment's FMU simulation, s (600)",
    )
    p.add_argument(
        "--fmu-isolate",
        action=argparse.BooleanOptionalAction,
        default=True,
        help="run the FMU in a forked child process, killed at the timeout; a crash is an "
        "error, not the end of clutchlab (default; ~15 ms per experiment). "
        "--no-fmu-isolate runs it in this process",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.add_argument("--json", help="also write metrics.json here")
    p.set_defaults(func=_cmd_evaluate, report_out=True, report_files=REPORT_FILES)
