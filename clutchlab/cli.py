"""``clutchlab`` command line: thin wrappers that parse arguments and call the layers."""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

from . import __version__
from .budgets import DEMO_BUDGET_S
from .cli_types import add_map_argument, nonnegative_int, positive_float
from .errors import ClutchlabError, DataError, OutputError

if TYPE_CHECKING:
    from .data import ReadOptions

__all__ = ["main"]


def _csv_list(text: str | None) -> tuple[str, ...]:
    return tuple(s.strip() for s in (text or "").split(",") if s.strip())


def usage_error(command: str, message: str) -> NoReturn:
    """Stop with ``clutchlab COMMAND: error: MESSAGE`` and exit status 2, as argparse does."""
    print(f"clutchlab {command}: error: {message}", file=sys.stderr)
    raise SystemExit(2)


def _list_plants(json_path: str | None = None) -> int:
    from .physics.stand.plants import PLANTS

    if json_path:
        doc = {
            "stand": {"summary": "clutchlab's own synthetic stand (the default)"},
            **{
                name: {"summary": spec.summary, "laws": spec.laws, "effects": list(spec.effects)}
                for name, spec in PLANTS.items()
            },
        }
        write_json_output(json_path, json.dumps(doc, indent=2, ensure_ascii=False))
    print("stand                 clutchlab's own synthetic stand (the default)")
    for name, spec in PLANTS.items():
        print(f"{name:21s} {spec.summary}")
        for component, law in spec.laws.items():
            print(f"{'':23s}{component}: {law}")
        print(
            f"{'':23s}effects it can carry (--effects; none by default): {', '.join(spec.effects)}"
        )
    return 0


#: Longest ramp ``clutchlab stand --ramps`` accepts, s (each of up and down; slow is 40).
MAX_RAMP_S = 3600.0


def _ramps(text: str | None):
    """``--ramps fast=2.5,r5=5,...`` as RampProfiles (the stand's three when None)."""
    from .physics.stand.scenarios import RAMPS, RampProfile

    if not text:
        return tuple(RAMPS.values())
    out, problems = [], []
    for item in _csv_list(text):
        label, sep, value = item.partition("=")
        try:
            seconds = float(value) if sep else float("nan")
        except ValueError:
            seconds = float("nan")
        if not label or not 0 < seconds <= MAX_RAMP_S:
            problems.append(f"{item!r} (want LABEL=SECONDS with 0 < SECONDS <= {MAX_RAMP_S:g})")
        else:
            out.append(RampProfile(label.strip(), seconds))
    labels = [r.label for r in out]
    if len(set(labels)) != len(labels):
        problems.append(f"repeated labels in {labels}")
    if problems:
        usage_error("stand", "--ramps: " + "; ".join(problems))
    return tuple(out)


def _cmd_stand(args: argparse.Namespace) -> int:
    from .physics.stand import DEFAULT_SETTINGS, StandConfig, order_ramps, truth_path, write_stand
    from .physics.stand.plants import PlantConfig, get_plant

    if args.list_plants:
        return _list_plants(args.json)
    if not args.out:
        usage_error("stand", "--out is required (or --list-plants)")
    n = args.settings
    if not 1 <= n <= len(DEFAULT_SETTINGS):
        usage_error("stand", f"--settings must be 1..{len(DEFAULT_SETTINGS)}")
    # Every (9 // n)-th setting in frequency-major order: 3 → 30/A, 50/A, 70/A (all three
    # frequencies, shape A); 5 to 8 → the first n. Kept so, though it spreads the shapes
    # less than it could: the recorded zoo studies (studies/discover_zoo.py, --settings 3)
    # were drawn from exactly these datasets.
    step = max(len(DEFAULT_SETTINGS) // n, 1)
    settings = DEFAULT_SETTINGS[::step][:n] if n < len(DEFAULT_SETTINGS) else DEFAULT_SETTINGS
    ramps = _ramps(args.ramps)
    check_json_apart(args.json, [Path(args.out), truth_path(args.out)])
    if args.plant == "stand":
        if args.temperature != "levels":
            usage_error("stand", "--temperature drift applies to the zoo's plants (--plant NAME)")
        config = StandConfig(
            effects=_csv_list(args.effects),
            builtin_effects=not args.no_builtin,
            settings=settings,
            ramps=ramps,
            seed=args.seed,
        )
        config.model()  # unknown effect names fail before any work
    else:
        if args.no_builtin:
            usage_error("stand", "--no-builtin applies to the stand only; a plant has no built-ins")
        config = PlantConfig(
            plant=args.plant,
            effects=_csv_list(args.effects),
            settings=settings,
            ramps=ramps,
            seed=args.seed,
            temperature=args.temperature,
        )
        get_plant(config.plant).check_effects(config.effects)  # refused before any work
    run = write_stand(args.out, config, overwrite=args.overwrite, progress=not args.quiet)
    out = Path(args.out)
    listed = order_ramps(run.dataset.ramps, {r.label: r.rate_mA_s for r in ramps})
    print(
        f"wrote {len(run.dataset)} experiments to {out} "
        f"(ramps: {', '.join(listed)}); overview {out / 'pressure_vs_current.png'}"
    )
    print(f"truth (effects, parameters) beside it: {truth_path(out)}")
    if args.json:
        write_json_output(
            args.json,
            json.dumps(
                {
                    "dataset": str(out),
                    "experiments": run.dataset.names,
                    "truth": str(truth_path(out)),
                },
                indent=2,
            ),
        )
    return 0


def _cmd_effects(args: argparse.Namespace) -> int:
    from .physics import effect_table

    table = effect_table()
    if args.json:
        write_json_output(args.json, json.dumps(table, indent=2, ensure_ascii=False))
    for row in table:
        print(f"{row['name']:32s} {row['description']}")
        print(f"{'':32s}   residual signature: {row['signature']}")
        print(f"{'':32s}   parameters: {row['parameters']} (off at zero: {row['strength']})")
    return 0


def _cmd_params(args: argparse.Namespace) -> int:
    from .physics import CircuitModel
    from .physics.units import unit_shown

    model = CircuitModel().with_effects(*_csv_list(args.effects))
    rows = [p.to_dict() for p in model.parameters]
    if args.json:
        write_json_output(args.json, json.dumps(rows, indent=2, ensure_ascii=False))
    if args.out:
        write_json_output(args.out, model.default_params().to_json())
    print(
        f"{'name':18s} {'default':>10s} {'unit':14s} {'[lower, upper]':16s} {'fit scale':12s} "
        "description"
    )
    for p in model.parameters:
        fit, bounds = f"{p.transform} {p.scale:g}", f"[{p.lower:g}, {p.upper:g}]"
        print(
            f"{p.name:18s} {p.default:10.4g} {unit_shown(p.unit):14s} {bounds:16s} "
            f"{fit:12s} {p.description}"
        )
    return 0


def _cmd_demo(args: argparse.Namespace) -> int:
    from .cli_eval import run_demo_command

    return run_demo_command(args)


def _read_options(args: argparse.Namespace) -> ReadOptions:
    from .data import ReadOptions

    return ReadOptions(interpolate_gaps=args.interpolate_gaps, rate_Hz=args.rate)


def _cmd_data_check(args: argparse.Namespace) -> int:
    from .data.check import check_path

    if not Path(args.path).exists():  # an error of the call, not a finding in the data
        raise DataError(f"{args.path}: no such file or folder")
    result = check_path(args.path, args.map, options=_read_options(args))
    if args.json:
        write_json_summary(args.json, result.to_dict())
    print(result.table())
    return 0 if result.ok else 1


def _cmd_data_convert(args: argparse.Namespace) -> int:
    from .data.convert import convert

    out = convert(
        args.src,
        args.dst,
        format=args.format,
        channel_map=args.map,
        options=_read_options(args),
        overwrite=args.overwrite,
    )
    print(f"wrote {out}")
    return 0


def _add_read_options(p: argparse.ArgumentParser) -> None:
    add_map_argument(p)
    p.add_argument(
        "--interpolate-gaps",
        type=int,
        default=0,
        metavar="N",
        help="fill NaN/inf runs and time gaps of up to N samples by interpolation (default 0)",
    )
    p.add_argument(
        "--rate", type=float, default=None, metavar="HZ", help="resample onto a grid at HZ"
    )


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``clutchlab`` command."""
    parser = argparse.ArgumentParser(prog="clutchlab", description=__doc__)
    parser.add_argument("--version", action="version", version=f"clutchlab {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("stand", help="run the synthetic test stand and write a dataset folder")
    p.add_argument("--out", help="dataset folder to create")
    p.add_argument(
        "--plant",
        default="stand",
        help="circuit to run: 'stand' (clutchlab's own, the default) or a plant of the zoo "
        "(see --list-plants)",
    )
    p.add_argument(
        "--list-plants", action="store_true", help="list the zoo's plants and their laws"
    )
    p.add_argument("--effects", default="", help="extra library effects, comma separated")
    p.add_argument(
        "--temperature",
        choices=("levels", "drift"),
        default="levels",
        help="oil temperature of a zoo plant's runs: fixed levels (40/55/70 °C by setting) or "
        "warming 40 → 85 °C through every run",
    )
    p.add_argument(
        "--no-builtin",
        action="store_true",
        help="without the stand's built-in effects (base model + noise only)",
    )
    p.add_argument(
        "--seed",
        type=nonnegative_int,
        default=0,
        help="seed of noise and wander (and, for a zoo plant, of its as-built unit)",
    )
    p.add_argument(
        "--settings",
        type=int,
        default=9,
        help="number of dither settings (1-9; default 9 = 3 frequencies × 3 shapes); fewer "
        "take every (9 // N)-th in frequency-major order: 3 = 30, 50, 70 Hz with shape A, "
        "5 to 8 = the first N",
    )
    p.add_argument(
        "--ramps",
        help="ramp labels and durations (s, each of the up and down ramps), e.g. "
        "fast=2.5,r5=5,medium=10,r20=20,slow=40 for held-back training-side rates "
        "(default fast=2.5,medium=10,slow=40)",
    )
    p.add_argument("--overwrite", action="store_true", help="replace an existing dataset folder")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--json", help="write a summary (with --list-plants: the list) as JSON here")
    p.set_defaults(func=_cmd_stand)

    p = sub.add_parser("effects", help="list the effect library")
    p.add_argument("--json", help="write the table as JSON here")
    p.set_defaults(func=_cmd_effects)

    p = sub.add_parser("params", help="list the model parameters (units, defaults, bounds)")
    p.add_argument("--effects", default="", help="effects switched on, comma separated")
    p.add_argument("--json", help="write the table as JSON here")
    p.add_argument(
        "--out",
        help="write the datasheet values as a parameter file to edit (a design before any "
        "fit; `clutchlab export-fmu FILE` exports it as an FMU)",
    )
    p.set_defaults(func=_cmd_params, file_out="json", out_writes="design")

    p = sub.add_parser("demo", help="stand data → physics fit → ML variants → report, end to end")
    p.add_argument("--out", default="clutchlab-demo", help="output folder (default clutchlab-demo)")
    p.add_argument("--variants", default="", help="comma separated (default: every available)")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.add_argument("--json", help="also write metrics.json here")
    budget = p.add_mutually_exclusive_group()
    budget.add_argument(
        "--budget",
        type=positive_float,
        default=DEMO_BUDGET_S,
        metavar="S",
        help=f"wall-time budget of the demo (s; default {DEMO_BUDGET_S:g}): the closing-the-"
        "loop discovery ends early enough for the rest to finish within it, keeping the "
        "model it had and saying so; give more on a slower machine to see it whole",
    )
    budget.add_argument(
        "--no-budget", action="store_true", help="no budget: the discovery runs to its end"
    )
    from .cli_eval import REPORT_FILES

    p.set_defaults(func=_cmd_demo, report_out=True, report_files=REPORT_FILES)

    p = sub.add_parser("data", help="test-stand data: check and convert logs and datasets")
    data = p.add_subparsers(dest="data_command", required=True)
    q = data.add_parser(
        "check",
        help="check a dataset folder or a log; table per experiment; exit 1 if anything is wrong",
        description="Check a dataset folder or one log: a table per experiment with every "
        "problem found. Exit status 0: everything readable and plausible; 1: problems found "
        "(listed, nothing written but --json); 2: the call could not be taken (no such path, "
        "a bad option or channel map).",
    )
    q.add_argument("path", help="dataset folder, manifest.json, or one .csv/.parquet/.mf4 log")
    _add_read_options(q)
    q.add_argument("--json", help="write the check result as JSON here")
    q.set_defaults(func=_cmd_data_check)
    q = data.add_parser(
        "convert",
        help="convert a dataset folder (or a log) to canonical names and units",
        description="Convert a dataset folder (or one log) to canonical names and units. Exit "
        "status 0: written; 2: refused, nothing written — the data's problems are listed "
        "(`clutchlab data check SRC` tabulates them per experiment) or the call could not be "
        "taken.",
    )
    q.add_argument("src", help="dataset folder, manifest.json, or one log file")
    q.add_argument("dst", help="destination folder (dataset) or file (single log)")
    q.add_argument(
        "--format",
        choices=("csv", "parquet", "mf4", "mat"),
        help="output format (default csv for a dataset, the suffix of DST for a file)",
    )
    q.add_argument("--overwrite", action="store_true", help="replace an existing destination")
    _add_read_options(q)
    q.set_defaults(func=_cmd_data_convert)
    from . import (
        cli_discover,
        cli_eval,
        cli_fit,
        cli_fmu,
        cli_ml,
        cli_predict,
        cli_structure,
        cli_sweep,
    )

    modules = (cli_fit, cli_structure, cli_ml, cli_eval, cli_predict, cli_discover, cli_fmu)
    for module in (*modules, cli_sweep):
        module.register(sub)
    return parser


def check_outputs(args: argparse.Namespace) -> None:
    """Check every output a command names before any work is done.

    - ``--json``, and a command's single-file ``--out`` (``file_out``: the kind of file it
      writes, e.g. ``"json"``): replaced without ``--overwrite`` when they hold an earlier
      result, so an existing file there must be of that kind and not one of the inputs
      (:func:`_check_replaceable`);
    - a model folder (``folder_out``, ``train``): a folder, and its ``model.json`` as above;
    - a report folder (``evaluate``, ``demo``, ``discover``) may exist: what clutchlab wrote
      there is replaced and every other file is kept (see :mod:`clutchlab.data.output`); a
      folder holding another kind of clutchlab output (a dataset) is refused;
    - ``--json`` must not name ``--out`` itself, nor a non-JSON file written in the ``--out``
      folder (``report_files``): one would be written over the other.
    """
    from .data.output import check_output

    if getattr(args, "json", None):
        check_output(args.json, kind="file", overwrite=True, what="--json")
        _check_replaceable(args.json, args, "--json", "json")
    out = getattr(args, "out", None)
    if out and getattr(args, "json", None):
        target, out_path = Path(os.path.abspath(args.json)), Path(os.path.abspath(out))
        if target == out_path:  # one wording for every command (stand and sweep use it too)
            check_json_apart(args.json, [Path(out)])
        if (
            target.parent == out_path
            and target.name in getattr(args, "report_files", ())
            and target.suffix != ".json"
        ):
            raise OutputError(
                f"--json {args.json}: is a file of {out}, which this command writes (--out); "
                "write the summary elsewhere"
            )
    folder = getattr(args, "report_out", False) or getattr(args, "folder_out", False)
    if out == "" and folder:
        raise OutputError("--out: an empty name; give the folder to write (e.g. report)")
    if not out:
        return
    if getattr(args, "file_out", None):
        check_output(out, kind="file", overwrite=True, what="--out")
        _check_replaceable(out, args, "--out", args.file_out)
    if getattr(args, "folder_out", False):
        from .data.output import owned_files
        from .residual_ml.persist import check_model_destination

        check_output(out, kind="folder", overwrite=True, what="--out")
        owned = owned_files(out)
        if owned:  # a dataset, a report: another kind of output is never written into it
            raise OutputError(
                f"--out {out}: holds other output clutchlab wrote ({len(owned)} files, e.g. "
                f"{sorted(owned)[0]}); write the model into a folder of its own"
            )
        _check_replaceable(Path(out) / "model.json", args, "--out", "json")
        # a user's model.json / model.npz there is refused now, not after the fit
        npz = check_model_destination(Path(out) / "model.json")
        # the summary is written last: over the model it would leave no model
        check_json_apart(getattr(args, "json", None), [Path(out) / "model.json", npz])
    if getattr(args, "report_out", False):
        from .data.output import check_report_out
        from .validation.report import REPORT_FOLDER

        # a user's report.html there is refused now, not after an hour of fitting
        check_report_out(out, getattr(args, "report_files", ()), kind=REPORT_FOLDER)


#: Arguments that name what a command writes, not what it reads.
_OUTPUT_ARGS = ("json", "out")


def _input_paths(args: argparse.Namespace) -> list[Path]:
    """Every existing file or folder a command's arguments name, outputs excepted."""
    found = []
    for key, value in vars(args).items():
        values = value if isinstance(value, list | tuple) else [value]
        for v in values:
            if key in _OUTPUT_ARGS or not isinstance(v, str | Path) or not str(v):
                continue
            with contextlib.suppress(OSError, ValueError):
                if Path(v).exists():
                    found.append(Path(v))
    return found


def _is_json(path: Path) -> bool:
    try:
        json.loads(path.read_bytes())
    except (OSError, ValueError):
        return False
    return True


def _is_zip(path: Path) -> bool:
    import zipfile

    return zipfile.is_zipfile(path)


#: The kinds of single-file output a command replaces: description, and the test of a file.
_REPLACEABLE = {"json": ("a JSON document", _is_json), "fmu": ("an FMU (zip archive)", _is_zip)}


def _check_replaceable(path: str | Path, args: argparse.Namespace, flag: str, kind: str) -> None:
    """Refuse an output file that exists and is not of the ``kind`` written, or is an input.

    ``--json`` and a fitted model's ``--out`` replace an earlier result of the same command
    without ``--overwrite``; they must never replace a user's log, map or manifest. So an
    existing file there is replaced only when it is of that kind and is neither one of the
    command's inputs nor the manifest of an input dataset folder.
    """
    from .data.manifest import MANIFEST_NAME

    target = Path(path)
    if not target.is_file():
        return
    for source in _input_paths(args):
        inside = source / MANIFEST_NAME if source.is_dir() else source
        same = False
        with contextlib.suppress(OSError):  # OutputError is an OSError: raised outside
            same = inside.exists() and os.path.samefile(inside, target)
        if same:
            raise OutputError(
                f"{flag} {target}: is {'the manifest of ' if source.is_dir() else ''}"
                f"this command's input {source}; write the result elsewhere"
            )
    description, looks_right = _REPLACEABLE[kind]
    if not looks_right(target):
        raise OutputError(
            f"{flag} {target}: exists and is not {description}, so clutchlab did not write "
            "it; choose another name (or remove the file)"
        )
    if kind == "json":
        # a --json summary never replaces a model, nor an --out one of another kind
        # (export-fmu --json fit.json once replaced the fit it had just exported)
        from .data import MODEL_FILE_KINDS, model_file_kind

        have = model_file_kind(target)
        writes = getattr(args, "out_writes" if flag == "--out" else "json_writes", None)
        if have is not None and have != writes:
            what = "this command's result" if writes else "a summary"
            raise OutputError(
                f"{flag} {target}: holds {MODEL_FILE_KINDS[have]}, which {what} would "
                "replace; choose another name"
            )


def check_json_apart(
    json_path: str | Path | None, outputs: list[Path], flag: str = "--out"
) -> None:
    """Refuse a ``--json`` that is one of the command's own outputs or lies inside one.

    The summary is written last, so ``--json r.parquet`` or ``--json DS/manifest.json`` would
    replace the results the command has just written (``OutputError``, before any work).

    Parameters
    ----------
    json_path : path or None
        The ``--json`` argument (nothing is checked when None).
    outputs : list of Path
        Files and folders the command writes.
    flag : str
        The argument the outputs come from, for the message.
    """
    if not json_path:
        return
    target = Path(json_path).resolve()
    for output in outputs:
        own = Path(output).resolve()
        if target == own or own in target.parents:
            raise OutputError(
                f"--json {json_path}: is {'inside ' if target != own else ''}{output}, which "
                f"this command writes ({flag}); write the summary elsewhere"
            )


def write_json_output(path: str | Path, text: str) -> Path:
    """Write a command's ``--json`` file atomically (replacing an earlier one)."""
    from .data.output import write_file_atomic

    return write_file_atomic(path, text.rstrip("\n").encode("utf-8") + b"\n", overwrite=True)


def write_json_summary(path: str | Path, doc: Any) -> Path:
    """Write a command's ``--json`` summary as strict JSON: a number that is not finite (the
    fit % of a constant experiment) is ``null``, not ``NaN``, which JSON readers refuse."""
    from .validation.report import jsonable

    text = json.dumps(jsonable(doc), indent=2, ensure_ascii=False, allow_nan=False)
    return write_json_output(path, text)


def _clean_warnings(command: str) -> None:
    """Show clutchlab's own warnings as one line for the user, not as source locations.

    Python's default shows ``path/cli_fit.py:107: FitWarning: ...`` and the source line;
    a warning of another library keeps that form (it helps report it upstream).
    """
    import warnings

    from .errors import FitWarning

    default = warnings.showwarning

    def show(message, category, filename, lineno, file=None, line=None):
        if issubclass(category, FitWarning) or category.__module__.startswith("clutchlab"):
            print(f"clutchlab {command}: warning: {message}", file=file or sys.stderr)
        else:
            default(message, category, filename, lineno, file, line)

    warnings.showwarning = show


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``clutchlab`` console script."""
    args = build_parser().parse_args(argv)
    command = " ".join(filter(None, [args.command, getattr(args, "data_command", None)]))
    _clean_warnings(command)
    try:
        check_outputs(args)
        return int(args.func(args) or 0)
    except ClutchlabError as exc:
        print(f"clutchlab {command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"\nclutchlab {command}: interrupted (Ctrl-C)", file=sys.stderr)
        return 130  # 128 + SIGINT, what a shell reports for an interrupted tool
    except BrokenPipeError:
        # The reader of our output went away (``clutchlab data check DS | head``): stop
        # quietly, as other command-line tools do, without a traceback at exit either.
        with contextlib.suppress(OSError, ValueError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141  # 128 + SIGPIPE, what a shell reports for a tool killed by it


if __name__ == "__main__":
    sys.exit(main())
