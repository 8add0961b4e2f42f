"""``clutchlab sweep``: a design study over model parameters and dither settings."""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

from .cli_types import nonnegative_float, positive_int

__all__ = ["register"]


def _cmd_sweep(args: argparse.Namespace) -> int:
    from .physics.design.runner import SweepInterrupted, SweepNote

    def note(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, SweepNote):
            print(f"note: {message}", file=sys.stderr)
        else:
            shown(message, category, filename, lineno, file, line)

    with warnings.catch_warnings():
        shown = warnings.showwarning
        warnings.simplefilter("always", SweepNote)
        warnings.showwarning = note
        try:
            return _run(args)
        except SweepInterrupted as exc:
            print(f"clutchlab sweep: {exc}", file=sys.stderr)
            return 130  # 128 + SIGINT, what a shell reports for a tool stopped by Ctrl-C
        except KeyboardInterrupt:
            print("clutchlab sweep: interrupted", file=sys.stderr)
            return 130


def _run(args: argparse.Namespace) -> int:
    from .cli import check_json_apart, usage_error
    from .physics.design import design_points, load_spec, run_sweep
    from .physics.design.runner import check_sweep_output

    if args.scheduler and args.workers is not None:
        usage_error("sweep", "--workers is for local runs; a Dask cluster has its own")
    spec = load_spec(args.spec)
    if not args.dry_run:  # before any work
        check_sweep_output(args.out, args.overwrite, figures=not args.no_figures)
        out = Path(args.out)
        siblings = [out.with_name(out.name + s) for s in (".lock", ".parts", ".figures")]
        check_json_apart(args.json, [out, *siblings])
    if args.dry_run:
        points = design_points(spec)
        print(
            f"{spec.name}: {len(points)} points ({spec.sampling.method}), "
            f"variables {', '.join(spec.variable_names) or '(none)'}; spec core {spec.core_hash}"
        )
        if args.json:
            from .cli import write_json_summary

            summary = {
                "name": spec.name,
                "dry_run": True,
                "n_points": len(points),
                "sampling": spec.sampling.method,
                "variables": list(spec.variable_names),
                "core_hash": spec.core_hash,
            }
            write_json_summary(args.json, summary)
        return 0
    res = run_sweep(
        spec,
        args.out,
        workers=args.workers,
        scheduler=args.scheduler,
        progress=not args.quiet,
        overwrite=args.overwrite,
        retry_failed=args.retry_failed,
        figures=not args.no_figures,
        flush_s=args.flush_s,
    )
    where = f"Dask {args.scheduler}" if args.scheduler else "local"
    print(
        f"{res.n_points} points: {res.n_run} run, {res.n_skipped} already done; "
        f"{res.n_failed} failed; {res.wall_s:.1f} s on {res.workers} {where} "
        f"worker{'s' if res.workers != 1 else ''} "
        f"({res.points_per_s:.2f} points/s)"
    )
    for f in res.summary()["failures"][:5]:
        print(f"  failed {f['point_id']}: {f['error']}")
    print(f"results: {res.out}")
    if res.figures:
        print(f"figures: {res.figures[0].parent}")
    if args.json:
        from .cli import write_json_summary

        write_json_summary(args.json, res.summary())
    if res.n_run and res.n_failed_run >= res.n_run:  # earlier calls' failures do not count
        print(f"every point failed ({res.n_failed_run}): see the errors above", file=sys.stderr)
        return 1
    return 0


def register(sub) -> None:
    """Add the ``sweep`` subcommand to the ``clutchlab`` parser."""
    p = sub.add_parser("sweep", help="design study: simulate a grid / Latin hypercube of designs")
    p.add_argument("spec", help="sweep spec (TOML): model, scenario, variables, sampling")
    p.add_argument("--out", required=True, help="results file (.parquet); parts and figures beside")
    p.add_argument("--scheduler", help="Dask scheduler address (tcp://host:8786): run there")
    p.add_argument(
        "--workers",
        type=positive_int,
        default=None,
        help="local worker processes, ≥ 1, at most one per batch (default: usable CPUs; 1 = here)",
    )
    p.add_argument(
        "--overwrite",
        action="store_true",
        help="discard existing results (and their figures) first",
    )
    p.add_argument("--retry-failed", action="store_true", help="run failed points again")
    p.add_argument("--no-figures", action="store_true", help="no tornado / scatter figures")
    p.add_argument(
        "--flush-s",
        type=nonnegative_float,
        default=5.0,
        metavar="S",
        help="write finished points to disk at least every S seconds, ≥ 0 (default 5; 0: after "
        "every batch)",
    )
    p.add_argument(
        "--dry-run",
        action="store_true",
        help="validate the spec, count the points (with --json: that count there); runs nothing",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--json", help="also write a summary here")
    p.set_defaults(func=_cmd_sweep)
