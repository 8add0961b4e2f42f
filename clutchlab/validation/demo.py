"""``clutchlab demo``: the embedded synthetic stand end to end, written as a report.

Stage of the project: the stand and the default-parameter physics model
(``physics_default``). Fitted physics and the ML variants join this report as
they land.
"""

from __future__ import annotations

import base64
import io
import json
import platform
import sys
import time
from pathlib import Path

import numpy as np
from tqdm.auto import tqdm

from .. import __version__
from ..data import Dataset, dither_period_mean, dither_period_samples, load_dataset
from ..physics import CircuitModel, simulate
from ..physics.stand import StandConfig, write_stand
from .metrics import pressure_metrics

__all__ = ["run_demo"]


def _stand_data(out: Path, progress: bool) -> tuple[Dataset, bool]:
    folder = out / "stand_data"
    if (folder / "manifest.json").exists():
        return load_dataset(folder), True
    write_stand(folder, StandConfig(), progress=progress, overwrite=True)
    return load_dataset(folder), False


def _period_avg(trace, p):
    return dither_period_mean(p, dither_period_samples(trace))


def run_demo(
    out: str | Path = "clutchlab-demo", progress: bool = True, command: str = "clutchlab demo"
) -> Path:
    """Generate (or re-use) stand data, score the physics baseline on the medium ramp, report.

    Parameters
    ----------
    out : path
        Output folder; stand data are cached in ``out/stand_data``.
    progress : bool
        Show progress bars.
    command : str
        The command line recorded in the report.

    Returns
    -------
    Path of ``report.html``.
    """
    from matplotlib.figure import Figure

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t_start = time.perf_counter()
    dataset, cached = _stand_data(out, progress)
    test = dataset.select(ramps=["medium"])
    model = CircuitModel()
    params = model.default_params()
    meas, pred, meas_raw, pred_raw, sims = [], [], [], [], {}
    t0 = time.perf_counter()
    for trace in tqdm(list(test), desc="physics_default", unit="exp", disable=not progress):
        res = simulate(model, params, trace)
        sims[trace.name] = res
        y = trace.get("clutch_pressure_bar")
        meas.append(_period_avg(trace, y))
        pred.append(_period_avg(trace, res.pressure_bar))
        meas_raw.append(y)
        pred_raw.append(res.pressure_bar)
    predict_s = time.perf_counter() - t0
    primary = pressure_metrics(np.concatenate(meas), np.concatenate(pred))
    raw = pressure_metrics(np.concatenate(meas_raw), np.concatenate(pred_raw))
    metrics = {
        "variants": {"physics_default": primary | {"fit_s": 0.0, "predict_s": predict_s}},
        "raw": {"physics_default": raw},
        "split": {
            "train": [t.name for t in dataset.select(ramps=["fast", "slow"])],
            "test": list(test.names),
        },
        "versions": {
            "clutchlab": __version__,
            "python": sys.version.split()[0],
            "platform": platform.platform(),
        },
        "command": command,
        "stand_data_cached": cached,
    }
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2) + "\n", encoding="utf-8")

    first = test[0]
    fig = Figure(figsize=(7.5, 5), layout="constrained")
    ax = fig.subplots()
    i_nom = first.get("current_cmd_mA")
    ax.plot(i_nom, meas[0], color="black", lw=1.0, label="measured (stand)")
    ax.plot(i_nom, pred[0], color="goldenrod", lw=1.0, label="physics_default")
    ax.set(
        xlabel="nominal VFS current (mA)",
        ylabel="clutch pressure, dither-period mean (bar)",
        title=f"Unseen medium ramp — {first.name}",
    )
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left")
    fig.savefig(out / "pressure_vs_current_medium.png", dpi=120)
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100)
    png = base64.b64encode(buf.getvalue()).decode()

    rows = "".join(
        f"<tr><td>{k}</td><td>{v:.4g}</td><td>{raw[k]:.4g}</td></tr>" for k, v in primary.items()
    )
    md_rows = "\n".join(f"| {k} | {v:.4g} | {raw[k]:.4g} |" for k, v in primary.items())
    elapsed = time.perf_counter() - t_start
    md = (
        f"# clutchlab demo report\n\nCommand: `{command}`  \nclutchlab {__version__}, "
        f"{len(dataset)} stand experiments, test = medium ramp ({len(test)} experiments), "
        f"{elapsed:.1f} s.\n\n## physics_default on the unseen medium ramp\n\n"
        f"| metric | dither-period mean | raw |\n|---|---|---|\n{md_rows}\n\n"
        "![pressure vs current](pressure_vs_current_medium.png)\n"
    )
    (out / "report.md").write_text(md, encoding="utf-8")
    html = (
        f"<!doctype html><html><head><meta charset='utf-8'><title>clutchlab demo</title>"
        f"</head><body style='font-family:sans-serif;max-width:900px'>"
        f"<h1>clutchlab demo report</h1><p>Command: <code>{command}</code><br>"
        f"clutchlab {__version__}; {len(dataset)} stand experiments; test = medium ramp "
        f"({len(test)} experiments); {elapsed:.1f} s.</p>"
        f"<h2>physics_default on the unseen medium ramp</h2><table border='1' "
        f"cellpadding='4'><tr><th>metric</th><th>dither-period mean</th><th>raw</th></tr>"
        f"{rows}</table><img src='data:image/png;base64,{png}' style='max-width:100%'>"
        f"</body></html>"
    )
    report = out / "report.html"
    report.write_text(html, encoding="utf-8")
    return report
