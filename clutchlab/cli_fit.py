"""``clutchlab fit-physics``: fit the physics model to a dataset's training experiments."""

from __future__ import annotations

import argparse
import sys
import warnings
from pathlib import Path

from .budgets import FIT_BUDGET_S
from .cli_types import add_map_argument, positive_float, print_dither_notes

__all__ = ["register"]


def _csv(text: str | None) -> tuple[str, ...]:
    return tuple(s.strip() for s in (text or "").split(",") if s.strip())


def limit_hint(status: str) -> str:
    """What may take a fit stopped at a limit further, from its (possibly staged) status
    ``"<status> (pre-fit) → <status> (refine)"``: the option of each limit a stage hit;
    ``""`` when no stage stopped at one (the solver stopped for another reason, which
    neither more time nor more iterations would change)."""
    from .physics.fit.fitter import SHORT_OF_TIME
    from .physics.fit.nlp import ITERATION_LIMIT, WALL_TIME_LIMIT

    stages = [part.strip() for part in status.split("→")]
    hints = []
    if any(ITERATION_LIMIT in st for st in stages):
        hints.append("more iterations (--max-iter)")
    if any(WALL_TIME_LIMIT in st or SHORT_OF_TIME in st for st in stages):
        hints.append("more time (--time-limit)")
    return " or ".join(hints) + " may improve it" if hints else ""


def plateau_note(status: str, settings) -> str:
    """What a ``Cost_Plateau`` stage status means, in the fit's own numbers (``""`` when no
    stage stopped on a plateau)."""
    from .physics.fit.nlp import COST_PLATEAU

    if COST_PLATEAU not in status:
        return ""
    return (
        f"({COST_PLATEAU}: the pre-fit's cost moved by less than "
        f"{100 * settings.prefit_obj_change_tol:g} % over its last "
        f"{settings.prefit_plateau_iter} iterations; more iterations would not lower it)"
    )


def fit_rate_note(dataset, settings) -> str:
    """What the fit does with training experiments logged faster than its rate: which it
    resamples (``--fit-rate``), or, without ``--fit-rate``, what fitting every sample costs
    (``""`` when no experiment is logged that fast)."""
    from .physics.fit import SUGGESTED_FIT_RATE_HZ, faster_than_fit

    rate = settings.fit_rate_Hz
    train = [t for t in dataset if t.ramp in settings.train_ramps]
    fast = [t for t in train if faster_than_fit(t, rate or SUGGESTED_FIT_RATE_HZ)]
    if not fast:
        return ""
    logged = ", ".join(sorted({f"{t.sample_rate_Hz:.6g}" for t in fast}))
    head = f"note: {len(fast)} of {len(train)} training experiments are logged at {logged} Hz"
    if rate is not None:
        return (
            f"{head}; they are fitted resampled to {rate:g} Hz (--fit-rate; --substeps sets "
            "the integration step)"
        )
    ratio = max(t.sample_rate_Hz for t in fast) / SUGGESTED_FIT_RATE_HZ
    return (
        f"{head}: the fit simulates every sample, so an iteration costs up to {ratio:.3g}× "
        f"one on {SUGGESTED_FIT_RATE_HZ:g} Hz data within the same time limit; "
        f"--fit-rate {SUGGESTED_FIT_RATE_HZ:g} fits them resampled to {SUGGESTED_FIT_RATE_HZ:g} Hz"
    )


def start_from_fit(path: str, effects: tuple[str, ...]):
    """The model and start of a fit that goes on from a saved fit.

    The saved fit's structure (its effects and flexible laws) plus ``effects``, started at
    its values; a law or effect it did not hold starts at its defaults, a held switch of
    one switched on (:func:`~clutchlab.physics.effects.flexible.switched_on`).

    Parameters
    ----------
    path : str
        A fit JSON written by ``clutchlab fit-physics`` (or :meth:`PhysicsFitter.save`).
    effects : tuple of str
        Effects and flexible laws to add to the saved fit's structure.

    Returns
    -------
    (CircuitModel, ParameterSet)
        The model to fit and its start.

    Raises
    ------
    FitError
        The file cannot be read or is not a fit result.
    """
    from .physics.effects.flexible import switched_on
    from .physics.fit import FitResult

    saved = FitResult.from_json(path)
    held = set(saved.effects)
    model = saved.model().with_effects(*(e for e in effects if e not in held))
    names = {p.name for p in model.parameters}
    start = model.params(**{k: v for k, v in saved.values.items() if k in names})
    new = {k: v for k, v in switched_on(model).items() if k not in saved.values}
    print(
        f"starting from {path} ({', '.join(saved.effects) or 'base circuit'}"
        + (f"; added {', '.join(e for e in effects if e not in held)}" if effects else "")
        + "): its values, no staged start"
    )
    return model, start.replace(**new) if new else start


def _worse_than_start(fitter, dataset, start) -> str:
    """Why a fit from ``--start`` ended worse than its start on the training experiments
    (RMS over them of each one's period-mean RMSE), or ``""``. A solver stage judges its
    own experiments only: a pre-fit on a subset can end where every training experiment
    is worse off than at the start."""
    from .physics.fit import training_rms

    before = training_rms(fitter.training_metrics(dataset, start))
    after = training_rms(fitter.result_.per_experiment)
    if after <= before:
        return ""
    return (
        f"the fit did not improve on its start: training RMSE {after:.4f} bar against "
        f"{before:.4f} at the start (RMS over the training experiments); the start stays "
        "the better model"
    )


def _latches_where_data_do_not(fitter, dataset, train) -> list[str]:
    """Training experiments on which the fitted model latches and the measurement never
    does (:func:`~clutchlab.physics.fit.latches_where_data_do_not`)."""
    from .physics.fit import FitSettings, latches_where_data_do_not

    names = set(train)
    traces = [t for t in dataset if t.name in names]
    substeps = (fitter.settings or FitSettings()).substeps
    return latches_where_data_do_not(fitter.model_, fitter.params_, traces, substeps)


def _cmd_fit_physics(args: argparse.Namespace) -> int:
    from .data import load_dataset
    from .errors import FitError, FitWarning
    from .physics import CircuitModel
    from .physics.fit import FitSettings, PhysicsFitter

    dataset = load_dataset(args.dataset, channel_map=args.map)
    print_dither_notes(dataset)
    model, start = CircuitModel().with_effects(*_csv(args.effects)), None
    if args.start:
        model, start = start_from_fit(args.start, _csv(args.effects))
    kw = {
        "train_ramps": _csv(args.train) or ("fast", "slow"),
        "progress": not args.quiet,
        "method": args.method,
        "time_limit_s": args.time_limit,
        "strict": args.strict,
        "staged_start": not args.no_staged_start,
        "latch_law": args.latch_law,
        "regulator_lag": args.regulator_lag,
        "latch_band": args.latch_band,
    }
    if args.free:
        kw["free"] = _csv(args.free)
    if args.substeps is not None:
        kw["substeps"] = args.substeps
    if args.max_iter is not None:
        kw["max_iter"] = args.max_iter
    if args.fit_rate is not None:
        kw["fit_rate_Hz"] = args.fit_rate
    settings = FitSettings(**kw)
    if note := fit_rate_note(dataset, settings):
        print(note)
    fitter = PhysicsFitter(model, settings, start=start)
    out = Path(args.out)
    try:
        with warnings.catch_warnings():
            # said below, with where the model went and what to do ("NOT CONVERGED")
            warnings.filterwarnings("ignore", "the fit stopped at a limit", FitWarning)
            fitter.fit(dataset)
    except FitError as exc:
        # A fit that ran and failed (--strict and stopped at a limit, or nothing improved
        # on the start) carries its best iterate and exits 1, as documented; bad input
        # (no result) stays an error of exit 2 (ClutchlabError in main).
        best = getattr(exc, "result", None)
        if best is None:
            raise
        partial = out.with_name(out.stem + ".best-iterate.json")
        best.to_json(partial)
        print(f"best iterate written to {partial}")
        print(f"clutchlab fit-physics: error: {exc}", file=sys.stderr)
        return 1
    res = fitter.result_
    if start is not None and (worse := _worse_than_start(fitter, dataset, start)):
        print(f"clutchlab fit-physics: error: {worse}; nothing written", file=sys.stderr)
        return 1
    fitter.save(out)
    if fitter.staged_ is not None:
        print(fitter.staged_.summary())
    print(f"structure: {', '.join(res.effects) or 'base circuit'}")
    print(res.table())
    print(f"\nstatus {res.status}, {res.iterations} iterations, {res.wall_s:.1f} s")
    note = plateau_note(res.status, fitter.settings or FitSettings())
    if note:
        print(note)
    if not res.success:
        hint = limit_hint(res.status)
        print(
            f"warning: NOT CONVERGED ({res.status}): "
            + (res.note or "the best iterate is the model")
            + f', written to {out} with "success": false; '
            + (f"{hint}, " if hint else "")
            + "--strict makes this an error",
            file=sys.stderr,
        )
    if res.unidentifiable:
        print(f"not identifiable from these data: {', '.join(res.unidentifiable)}")
    for name, m in res.per_experiment.items():
        print(f"  {name:20s} RMSE {m['rmse_bar']:.4f} bar  fit {m['fit_pct']:.1f} %")
    if spurious := _latches_where_data_do_not(fitter, dataset, res.train):
        print(
            f"note: the model latches on {', '.join(spurious)}, where the measured clutch "
            "pressure never reaches line pressure: the circuit's latch does not trip at "
            "that dither setting (a dwell latch or a filtered latch pilot under a large, "
            "slow dither), which the model's latch does not follow"
        )
    print(f"model written to {out}")
    if args.json:
        from .cli import write_json_output

        write_json_output(args.json, res.to_json())
    return 0


def register(sub) -> None:
    """Add the ``fit-physics`` subcommand to the ``clutchlab`` parser."""
    p = sub.add_parser("fit-physics", help="fit the physics model to training experiments")
    p.add_argument("dataset", help="dataset folder (manifest.json + experiments)")
    add_map_argument(p)
    p.add_argument("--out", required=True, help="fitted model JSON to write")
    p.add_argument("--effects", default="", help="effects switched on, comma separated")
    p.add_argument("--free", default="", help="free parameters (default: the standard set)")
    p.add_argument("--train", default="fast,slow", help="training ramp labels (fast,slow)")
    p.add_argument(
        "--method", default="single_shooting", choices=["single_shooting", "multiple_shooting"]
    )
    p.add_argument(
        "--time-limit",
        type=positive_float,
        default=FIT_BUDGET_S,
        help=f"wall limit of the whole fit (s; default {FIT_BUDGET_S:g}, the fit budget); the "
        "best iterate "
        "found by then is the model",
    )
    p.add_argument(
        "--max-iter",
        type=int,
        help="solver iterations of the fit's main stage (default 50; the refinement on all "
        "training data keeps its own few)",
    )
    p.add_argument(
        "--start",
        metavar="FIT.json",
        help="go on from a saved fit: its structure (plus --effects) and its values as the "
        "start, no staged start (e.g. to add a flexible law to a fit already made)",
    )
    p.add_argument(
        "--no-staged-start",
        action="store_true",
        help="start the full fit from the datasheet values (default: static characteristic "
        "and latch thresholds from the quasi-static data first)",
    )
    p.add_argument(
        "--latch-law",
        choices=("auto", "datasheet"),
        default="auto",
        help="auto: free latch thresholds when the data violate the datasheet latch's area "
        "ratio (default); datasheet: keep the datasheet latch",
    )
    p.add_argument(
        "--regulator-lag",
        choices=("auto", "off"),
        default="auto",
        help="auto (default): when the training data's regulated band widens with ramp rate "
        "more than the latch delay allows (lag signature, logged), add the reg_pilot_lag law "
        "and choose the latch port (feedback exhaust or latch_line_select) on the fast "
        "ramps; off: never",
    )
    p.add_argument(
        "--latch-band",
        choices=("auto", "band", "off"),
        default="auto",
        help="auto (default): when the slow training ramps' latch snaps move with the dither "
        "amplitude and frequency, or with the logged line pressure, more than the latch "
        "thresholds can follow (leave-one-experiment-out, logged), add latch_dither_band "
        "and / or latch_line_threshold after the solver, held at the snaps' values, kept "
        "only when they lower the training RMSE; with latch_dither_band added, the faster "
        "ramps' snaps are tested the same way for latch_rate_band (the band changing with "
        "the ramp rate); where neither band law is added, the slow and fastest ramps' "
        "latch-on snaps are tested the same way for latch_on_lag (the latch-on delayed "
        "with the rising ramp rate, the release not); band: the dither band law only (the "
        "default before session 59; the rate and latch-on stages still run); off: never",
    )
    p.add_argument(
        "--strict",
        action="store_true",
        help="a fit stopped at a limit is an error (exit 1, best iterate to "
        "OUT.best-iterate.json); default: the best iterate is the model, marked not converged",
    )
    p.add_argument(
        "--substeps",
        type=int,
        help="ROS2 integration steps per sample during the fit (default 2); more for a "
        "circuit whose simulation diverges at the default (slower in proportion)",
    )
    p.add_argument(
        "--fit-rate",
        type=float,
        metavar="HZ",
        help="sample rate of the fit: training experiments logged faster than 1.5 × this "
        "are resampled to it first (default: every sample is fitted; a hint is printed for "
        "data logged faster than 1.5 kHz)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--json", help="also write the fit result here")
    p.set_defaults(func=_cmd_fit_physics, file_out="json", out_writes="fit", json_writes="fit")
