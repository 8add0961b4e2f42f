"""``clutchlab classifiers`` and ``clutchlab train``: the paper's pipeline from the command line."""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

from .cli_types import add_map_argument, print_dither_notes

__all__ = ["register"]


def _csv(text: str | None) -> tuple[str, ...]:
    return tuple(s.strip() for s in (text or "").split(",") if s.strip())


def _training(dataset, ramps: tuple[str, ...]):
    from .errors import DataError

    if not ramps:
        raise DataError("--train needs at least one ramp label")
    train = dataset.select(ramps=list(ramps))
    if len(train) == 0:
        raise DataError(f"no experiments with ramp {', '.join(ramps)}")
    return train


def _cmd_classifiers(args: argparse.Namespace) -> int:
    from .data import load_dataset, write_folder_atomic
    from .errors import ModelError
    from .residual_ml import CLASSIFIERS, compare_classifiers

    out = Path(args.out)
    _check_classifiers_out(out)
    dataset = load_dataset(args.dataset, channel_map=args.map)
    print_dither_notes(dataset)
    train = _training(dataset, _csv(args.train))
    names = list(dict.fromkeys(_csv(args.classifiers))) or None  # each one once
    unknown = sorted(set(names or []) - set(CLASSIFIERS))
    if unknown:
        raise ModelError(f"unknown classifier(s) {unknown}; known: {', '.join(CLASSIFIERS)}")
    result = compare_classifiers(list(train), names=names, progress=not args.quiet)
    fig = result.figure()
    files = {
        "classifiers.csv": result.csv_text().encode("utf-8"),
        "classifiers.png": lambda path: fig.savefig(path, dpi=120, format="png"),
    }
    write_folder_atomic(out, files, overwrite=True, what=CLASSIFIER_FOLDER)
    print(
        f"latch classifiers, leave-one-experiment-out over {len(train)} training experiments "
        f"({', '.join(_csv(args.train))}); features: {', '.join(result.feature_names)}"
    )
    print(result.table())
    print(f"table: {out / 'classifiers.csv'}; figure: {out / 'classifiers.png'}")
    if args.json:
        from .cli import write_json_summary

        write_json_summary(args.json, result.to_dict())
    return 0


#: What ``clutchlab classifiers`` writes into its ``--out`` folder (see _cmd_classifiers).
CLASSIFIER_FILES = ("classifiers.csv", "classifiers.png")
#: The kind of that folder in its ownership record (see clutchlab.data.output).
CLASSIFIER_FOLDER = "classifier comparison folder"


def _check_classifiers_out(out: Path) -> None:
    """Refuse an ``--out`` folder the comparison could not be written to, before the work.

    The same refusals :func:`~clutchlab.data.write_folder_atomic` makes when writing (a
    file where the folder goes, another kind of clutchlab output, a user's file of the
    same name as one written), made before the leave-one-experiment-out fits.

    Raises
    ------
    OutputError
        Naming the folder and the reason.
    """
    from .data.output import check_folder_files, check_folder_kind, check_output

    check_output(out, kind="folder", overwrite=True, what="--out", whole=True)
    check_folder_kind(out, CLASSIFIER_FOLDER)
    check_folder_files(out, CLASSIFIER_FILES, what=CLASSIFIER_FOLDER)


def _physics(path: str | None):
    if not path:
        return None
    from .residual_ml import PhysicsPredictor

    if PhysicsPredictor.describes(path):  # its problems are its own, not a fit result's
        return PhysicsPredictor.load(path)
    from .physics.fit import PhysicsFitter

    return PhysicsPredictor.from_fitter(PhysicsFitter.load(path))


#: ``train`` variants with a latched GP whose reference ``--latched-reference`` sets (the
#: hybrid's residual has none: its physics prediction already follows line pressure).
LATCHED_REFERENCE_VARIANTS = ("paper_svc_gp", "paper_faithful")


def _cmd_train(args: argparse.Namespace) -> int:
    from tqdm.auto import tqdm

    from .data import load_dataset
    from .errors import ModelError
    from .residual_ml import SVCPartitionedGP, make_variant, score_traces
    from .residual_ml.features import PHYSICS_FEATURES, causal_features
    from .residual_ml.hybrid import HYBRID_FEATURES

    partitioned = {"latched_reference": args.latched_reference} if args.latched_reference else {}
    if partitioned and args.variant not in LATCHED_REFERENCE_VARIANTS:
        raise ModelError(
            f"--latched-reference is only used by {' and '.join(LATCHED_REFERENCE_VARIANTS)}; "
            f"{args.variant} has no latched GP of its own on the line pressure"
        )
    dataset = load_dataset(args.dataset, channel_map=args.map)
    print_dither_notes(dataset)
    train = _training(dataset, _csv(args.train))
    params = {}
    if args.variant == "hybrid":
        params["physics"] = _physics(args.physics)
        if args.causal:
            # the physics features are centred dither-period means with no causal form yet
            own = tuple(f for f in HYBRID_FEATURES if f not in PHYSICS_FEATURES)
            params["residual"] = SVCPartitionedGP(
                features=causal_features(own), kernel=args.kernel or None
            )
    else:
        if args.physics:
            raise ModelError("--physics is only used by the hybrid variant")
        if args.causal:
            params["features"] = causal_features(make_variant(args.variant)._builder().names)
        params |= partitioned
    if args.kernel and "residual" not in params:
        # every variant's own kernel parameter; the hybrid's sets its default residual
        # model and the standalone form made from it (HybridModel(kernel=...))
        params["kernel"] = args.kernel
    model = make_variant(args.variant, **params)
    if args.causal and not args.quiet:
        names = model.residual._builder().names if args.variant == "hybrid" else None
        names = names or model._builder().names
        print(f"causal features (past samples only): {', '.join(names)}")
    if not args.quiet:
        print(f"fitting {args.variant} on {len(train)} experiments ({', '.join(train.names)})")
    t0 = time.perf_counter()
    model.fit(train)
    fit_s = time.perf_counter() - t0
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    model.save(out / "model.json")
    overall = score_traces(model, tqdm(list(train), desc="scoring", disable=args.quiet))
    per = overall["per_experiment"]
    head = ("experiment", "RMSE (bar)", "MAE (bar)", "max|e| (bar)", "fit %")
    print(f"{head[0]:24s} {head[1]:>10s} {head[2]:>10s} {head[3]:>12s} {head[4]:>7s}")
    for name, m in per.items():
        print(
            f"{name:24s} {m['rmse_bar']:10.4f} {m['mae_bar']:10.4f} {m['max_abs_bar']:12.4f} "
            f"{m['fit_pct']:7.2f}"
        )
    o = overall["overall"]
    print(
        f"{'all training':24s} {o['rmse_bar']:10.4f} {o['mae_bar']:10.4f} "
        f"{o['max_abs_bar']:12.4f} {o['fit_pct']:7.2f}"
    )
    print(f"fit {fit_s:.1f} s; model written to {out / 'model.json'} (+ model.npz)")
    form = _hybrid_form(model)
    if form:
        print(f"hybrid form: {form}")
    latch = _latch_decision(model)
    if latch:
        print(f"latch decision: {latch}")
    never = _never_latched_note(model, train)
    if never:
        print(f"note: {never}", file=sys.stderr)
    for part, h in model.gp_hyperparameters().items():
        ell = ", ".join(f"{v:.3g}" for v in h["length_scales"])
        print(
            f"GP {part}: {h['kernel']}, length scales [{ell}] (feature units), "
            + (f"alpha {h['alpha']:.3g}, " if h["alpha"] is not None else "")
            + f"noise var {h['noise_var']:.3g} bar²"
        )
    bound = model.hyperparameters_at_bounds()
    if bound:
        print(
            "warning: GP hyperparameter(s) on a bound of their range (the likelihood wanted a "
            "value outside it): " + "; ".join(bound),
            file=sys.stderr,
        )
    if args.json:
        doc = {
            "variant": args.variant,
            "causal": bool(args.causal),
            "features": list(model.feature_names_),
            "dataset": str(args.dataset),
            # how the logs were read (a manifest's map or --map), for repeating the training
            "channel_maps": dataset.channel_maps,
            "train": train.names,
            "fit_s": fit_s,
            "predict_s": overall["predict_s"],
            "training": {"overall": o, "per_experiment": per},
            "model": str(out / "model.json"),
            "gp_hyperparameters": model.gp_hyperparameters(),
            "hyperparameters_at_bounds": bound,
            "latch_decision": latch,
        }
        if form:
            doc["hybrid_form"] = model.form_
            doc["hybrid_form_loeo_rmse_bar"] = dict(model.form_scores_)
            kappa = float(getattr(model, "standalone_handicap_", math.nan))
            doc["hybrid_standalone_handicap"] = kappa if math.isfinite(kappa) else None
        from .cli import write_json_summary

        write_json_summary(args.json, doc)
    return 0


def register(sub) -> None:
    """Add the ``classifiers`` and ``train`` subcommands to the ``clutchlab`` parser."""
    from .residual_ml import CLASSIFIERS, VARIANTS

    p = sub.add_parser(
        "classifiers",
        help="compare the six latch classifiers by leave-one-experiment-out (table + figure)",
    )
    p.add_argument("dataset", help="dataset folder (manifest.json + experiments)")
    add_map_argument(p)
    p.add_argument("--out", default="classifiers", help="folder for classifiers.csv/.png")
    p.add_argument(
        "--classifiers",
        default="",
        help="comma-separated subset of: " + ", ".join(CLASSIFIERS) + " (default all six)",
    )
    p.add_argument("--train", default="fast,slow", help="training ramp labels (fast,slow)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--json", help="also write the result here")
    p.set_defaults(func=_cmd_classifiers, report_files=CLASSIFIER_FILES)

    p = sub.add_parser("train", help="train a paper-pipeline model variant on training ramps")
    p.add_argument("dataset", help="dataset folder (manifest.json + experiments)")
    add_map_argument(p)
    p.add_argument("--variant", required=True, choices=list(VARIANTS), help="model variant")
    p.add_argument("--out", required=True, help="folder for model.json + model.npz")
    p.add_argument("--train", default="fast,slow", help="training ramp labels (fast,slow)")
    p.add_argument(
        "--kernel",
        choices=["rq", "rbf"],
        help="GP kernel (default: the variant's, chosen by leave-one-experiment-out)",
    )
    p.add_argument(
        "--physics",
        help="hybrid only: physics model JSON (PhysicsPredictor or fit-physics output); "
        "default: datasheet parameters",
    )
    p.add_argument(
        "--causal",
        action="store_true",
        help="causal features (trailing-window dI/dt and direction, no look-ahead) so that "
        "`clutchlab export-fmu` reproduces the model exactly; hybrid: the residual model "
        "uses I, A_d, f_d and the causal dI/dt and direction (no physics features)",
    )
    p.add_argument(
        "--latched-reference",
        choices=["line", "none"],
        help="paper_svc_gp and paper_faithful: learn the latched "
        "plateau relative to the logged line pressure (line; clutchlab's default, the paper's "
        "is none) or as the pressure itself (none: the model then predicts where line "
        "pressure is not logged)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--json", help="also write the training metrics here")
    p.set_defaults(func=_cmd_train, folder_out=True, out_writes="ml")


def _hybrid_form(model) -> str | None:
    """Which form a fitted hybrid predicts with, and the training-set scores behind it."""
    form = getattr(model, "form_", None)
    if form is None:
        return None
    scores = getattr(model, "form_scores_", {}) or {}
    why = ", ".join(f"{k} {v:.4g} bar" for k, v in scores.items())
    handicap = float(getattr(model, "standalone_handicap_", math.nan))
    if "standalone" in scores and math.isfinite(handicap):
        why += f"; standalone compared after ÷ {handicap:.3g}"
    text = form + (f" (leave-one-experiment-out RMSE on the training ramps: {why})" if why else "")
    if form == "physics":
        text += "; predicts with the physics model alone, the residual model below is not used"
    elif form == "standalone":
        text += "; predicts with the paper pipeline alone, the physics model is not used"
    return text


def _never_latched_note(model, train) -> str | None:
    """Why a model found one latch state only: how close the clutch came to line pressure.

    A circuit whose latched plateau sits more than the label rule's margin below the logged
    (or, unlogged, the assumed 17.7 bar) line pressure is never labelled latched, and the
    model then has no latch at all; the engineer should see the numbers behind that.
    """
    import numpy as np

    from .data import LINE_PRESSURE_BAR, dither_period_mean, dither_period_samples

    est = getattr(model, "residual_", None) or model
    if getattr(est, "latch_model_", None) != "none" or getattr(est, "single_state_", None) != 0:
        return None  # a latch decision, or only latched samples
    rule = est._rule()
    closest, assumed = np.inf, False
    for t in train:
        n = dither_period_samples(t)
        assumed |= not t.has("line_pressure_bar")
        gap = dither_period_mean(t.get("line_pressure_bar"), n) - dither_period_mean(
            t.get("clutch_pressure_bar"), n
        )
        closest = min(closest, float(np.min(gap)))
    line = (
        f"line pressure not logged in every experiment, {LINE_PRESSURE_BAR:g} bar assumed there; "
        if assumed
        else ""
    )
    return (
        f"no training sample was labelled latched: the clutch pressure came within "
        f"{closest:.2f} bar of line pressure at the closest ({line}latched means within "
        f"{rule.margin_bar:g} bar, dither-period means). If the clutch latches in these data, "
        "log line_pressure_bar or check the pressure offsets."
    )


def _latch_decision(model) -> str | None:
    """What decides the latch state of ``model`` (the report's words too)."""
    from .residual_ml import latch_decision_text

    return latch_decision_text(model)
