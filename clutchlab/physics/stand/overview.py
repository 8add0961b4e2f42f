"""Overview figure of a stand dataset: clutch pressure vs current for each ramp."""

from __future__ import annotations

import numpy as np

from ...data import Dataset, dither_period_mean, dither_period_samples
from .scenarios import DitherSetting, order_ramps

__all__ = ["plot_pressure_vs_current"]

_COLORS = {"fast": "tab:blue", "medium": "black", "slow": "tab:green"}
#: Colours of other ramp labels (``--ramps r5=5,...``), in order: none of the three above.
_OTHER_COLORS = (
    "tab:orange",
    "tab:red",
    "tab:purple",
    "tab:brown",
    "tab:pink",
    "tab:olive",
    "tab:cyan",
    "tab:gray",
)


def _setting_tag(trace) -> str:
    """The dither tag (``50Hz_B``) of a stand experiment: from its metadata, else its name."""
    freq, shape = trace.meta.get("dither_freq_Hz"), trace.meta.get("dither_shape")
    if isinstance(freq, int | float) and isinstance(shape, str):
        return DitherSetting(float(freq), shape).tag
    return "_".join(trace.name.rsplit("_", 2)[1:])  # <ramp label>_<freq>Hz_<shape>


def _command_ramp_rate(trace) -> float | None:
    """Ramp rate of an experiment (mA/s), from its current command ``current_cmd_mA``.

    The 95th percentile of |dI/dt| over the samples where the command changes, to 6
    significant digits: the rate of a piecewise-linear ramp (the holds left out), equal for
    equal ramps; None when the command never changes.
    """
    t, cmd = trace.time_s, trace.get("current_cmd_mA")
    if len(t) < 2:
        return None
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = np.abs(np.gradient(cmd, t))
    moving = slope[np.isfinite(slope) & (slope > 0)]
    return float(f"{np.percentile(moving, 95):.6g}") if moving.size else None


def plot_pressure_vs_current(dataset: Dataset, setting: str | None = None):
    """Clutch pressure (dither-period averaged, bar) vs nominal current (mA), per ramp.

    Parameters
    ----------
    dataset : Dataset
        Stand or test-stand dataset with ``current_cmd_mA``.
    setting : str, optional
        Only experiments of this dither setting (tag, e.g. ``50Hz_A``); the first
        experiment's when omitted.

    Returns
    -------
    matplotlib.figure.Figure
        One line per ramp, fastest ramp first (the rate of its current command;
        alphabetical among equal rates, ramps without one last); ``fast`` / ``medium`` /
        ``slow`` in blue / black / green, every other ramp label in a colour of its own.
    """
    from matplotlib.figure import Figure  # imported on use: simulation workers never draw

    fig = Figure(figsize=(7.5, 5), layout="constrained")  # no pyplot: no global backend
    ax = fig.subplots()
    tag = setting or (_setting_tag(dataset[0]) if len(dataset) else "")
    others: dict[str, str] = {}
    shown = [t for t in dataset if _setting_tag(t) == tag and t.has("current_cmd_mA")]
    rates: dict[str, float | None] = {}
    for trace in shown:  # a label's fastest experiment (one each, in a stand dataset)
        label, rate = str(trace.ramp), _command_ramp_rate(trace)
        rates[label] = max(filter(None, (rates.get(label), rate)), default=None)
    rank = {label: k for k, label in enumerate(order_ramps(rates, rates))}
    for trace in sorted(shown, key=lambda t: rank[str(t.ramp)]):  # stable sort
        if trace.ramp not in _COLORS and trace.ramp not in others:
            others[trace.ramp] = _OTHER_COLORS[len(others) % len(_OTHER_COLORS)]
        p = dither_period_mean(trace.get("clutch_pressure_bar"), dither_period_samples(trace))
        ax.plot(
            trace.get("current_cmd_mA"),
            p,
            lw=0.9,
            color=_COLORS.get(trace.ramp) or others[trace.ramp],
            label=f"{trace.ramp} ({trace.name})",
        )
    ax.set(
        xlabel="nominal VFS current (mA)",
        ylabel="clutch pressure, dither-period mean (bar)",
        title=f"Clutch pressure vs current — dither {tag}",
    )
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left")
    return fig
