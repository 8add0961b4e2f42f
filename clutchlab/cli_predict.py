"""``clutchlab predict``: a saved model on a dataset — predictions, scores and figures."""

from __future__ import annotations

import argparse
from pathlib import Path

from .cli_types import add_map_argument

__all__ = ["register"]

#: The kind of a ``predict --out`` folder in its ownership record (clutchlab.data.output).
PREDICTION_FOLDER = "prediction folder"


def _names(text: str | None) -> list[str] | None:
    names = [s.strip() for s in (text or "").split(",") if s.strip()]
    return names or None


def _frame_writer(columns: dict, fmt: str):
    """Write one experiment's per-sample table to the path it is given."""

    def write(path: Path) -> None:
        import pandas as pd

        frame = pd.DataFrame(columns)
        if fmt == "parquet":
            frame.to_parquet(path, index=False)
        else:
            frame.to_csv(path, index=False, float_format="%.6g", lineterminator="\n")

    return write


def _figure_writer(prediction):
    def write(path: Path) -> None:
        from .validation.predict_figure import prediction_figure

        fig = prediction_figure(prediction)
        fig.savefig(path, dpi=110, format="png")

    return write


def _metrics_csv(predictions) -> bytes:
    """One row per experiment: its scores (bar, %) and the window they average over
    (``window_samples``, ``window_ms``: one dither period; 1 sample, the raw signal, for a
    log without a dither)."""
    rows = ["experiment,ramp,trained,rmse_bar,mae_bar,max_abs_bar,fit_pct,window_samples,window_ms"]
    for p in predictions:
        m, w = p.metrics, p.averaging or {}
        rows.append(
            f"{p.name},{p.ramp},{int(p.trained)},{m['rmse_bar']:.6g},{m['mae_bar']:.6g},"
            f"{m['max_abs_bar']:.6g},{m['fit_pct']:.6g},{p.period_samples:.6g},"
            f"{_g(w.get('window_ms'))}"
        )
    return ("\n".join(rows) + "\n").encode("utf-8")


def _g(value) -> str:
    return "" if value is None else f"{value:.6g}"


def _cmd_predict(args: argparse.Namespace) -> int:
    from tqdm.auto import tqdm

    from .data import load_dataset, write_folder_atomic
    from .data.output import check_report_out
    from .validation.averaging import averaging_note, scored_signal
    from .validation.predict import (
        load_predictor,
        overall_metrics,
        predict_traces,
        prediction_table,
    )

    loaded = load_predictor(args.model, args.substeps)  # checked before the data are read
    if args.std:
        loaded.check_std(f"--std: {args.model}: ")
    dataset = load_dataset(args.dataset, channel_map=args.map)
    chosen = dataset.select(ramps=_names(args.ramps), names=_names(args.experiments))
    ext = "parquet" if args.format == "parquet" else "csv"
    files = {f"predictions/{t.name}.{ext}" for t in chosen}
    if args.figures:
        files |= {f"figures/{t.name}.png" for t in chosen}
    files.add("metrics.csv")
    out = Path(args.out)
    check_report_out(out, sorted(files), kind=PREDICTION_FOLDER)  # before the predictions
    if not args.quiet:
        print(f"predicting {len(chosen)} experiments with the {loaded.kind} {args.model}")
    bar = None if args.quiet else (lambda it: tqdm(it, desc="predict", unit="experiment"))
    predictions, wall = predict_traces(loaded, list(chosen), with_std=args.std, progress=bar)
    content = {"metrics.csv": _metrics_csv(predictions)}
    for p in predictions:
        content[f"predictions/{p.name}.{ext}"] = _frame_writer(p.columns(), args.format)
        if args.figures:
            content[f"figures/{p.name}.png"] = _figure_writer(p)
    write_folder_atomic(out, content, overwrite=True, what=PREDICTION_FOLDER)
    print(prediction_table(predictions))
    n_train = sum(p.trained for p in predictions)
    if n_train:
        print(
            f"note: {n_train} of these experiments were used to train or fit the model "
            "(marked train): their scores are in-sample"
        )
    windows = {p.name: p.averaging for p in predictions if p.averaging}
    if scored_signal(windows) != scored_signal(None):
        print(averaging_note(windows))
    print(
        f"scores on the {scored_signal(windows)}; predictions {wall:.1f} s; written to {out} "
        f"(predictions/*.{ext}, metrics.csv" + (", figures/*.png)" if args.figures else ")")
    )
    if args.json:
        from .cli import write_json_summary

        write_json_summary(
            args.json,
            {
                "model": str(args.model),
                "model_kind": loaded.kind,
                "dataset": str(args.dataset),
                "out": str(out),
                "predict_s": wall,
                "overall": dict(
                    zip(("metrics", "experiments"), overall_metrics(predictions), strict=True)
                ),
                "experiments": {
                    p.name: {
                        "ramp": p.ramp,
                        "trained": p.trained,
                        **p.metrics,
                        "averaging": p.averaging,
                    }
                    for p in predictions
                },
            },
        )
    return 0


def register(sub) -> None:
    """Add the ``predict`` subcommand to the ``clutchlab`` parser."""
    p = sub.add_parser(
        "predict",
        help="predict a dataset's clutch pressure with a saved model; score it and plot it",
        description=(
            "Predict the clutch pressure of a dataset's experiments with a model saved earlier, "
            "without fitting anything: a `clutchlab train` model.json, a `fit-physics` result, "
            "a `params --out` design file or an FMU (`export-fmu`'s). Writes "
            "predictions/<experiment>.csv (time, nominal current, measured, predicted, "
            "residual [, std]), metrics.csv (RMSE, MAE, max |e| and fit % of the dither-period "
            "means, as `evaluate` scores, and the averaging window: 1 sample, the raw signal, "
            "for a log without a dither) and figures/<experiment>.png into --out. Experiments "
            "the model was trained on are marked: their scores are in-sample. Exit status 0: "
            "written; 2: refused, nothing written."
        ),
    )
    p.add_argument(
        "model", help="model file: train's model.json, fit-physics JSON, design file or FMU"
    )
    p.add_argument("dataset", help="dataset folder (manifest.json + experiments)")
    add_map_argument(p)
    p.add_argument("--out", required=True, help="folder to write the predictions into")
    p.add_argument("--ramps", help="only experiments of these ramp labels (e.g. medium)")
    p.add_argument("--experiments", help="only these experiments (comma-separated names)")
    p.add_argument(
        "--std",
        action="store_true",
        help="also the predictive standard deviation (bar; GP models)",
    )
    p.add_argument(
        "--substeps",
        type=int,
        default=None,
        help="physics models: ROS2 steps per sample, 1..64 (default 4, as evaluate scores)",
    )
    p.add_argument(
        "--format",
        choices=("csv", "parquet"),
        default="csv",
        help="format of the per-sample predictions (default csv)",
    )
    p.add_argument("--no-figures", dest="figures", action="store_false", help="no figures (faster)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--json", help="also write the scores here")
    p.set_defaults(func=_cmd_predict)
