"""Overview figure of a stand dataset: clutch pressure vs current for each ramp."""

from __future__ import annotations

from ...data import Dataset, dither_period_mean, dither_period_samples

__all__ = ["plot_pressure_vs_current"]

_COLORS = {"fast": "tab:blue", "medium": "black", "slow": "tab:green"}


def plot_pressure_vs_current(dataset: Dataset, setting: str | None = None):
    """Clutch pressure (dither-period averaged, bar) vs nominal current (mA), per ramp.

    Parameters
    ----------
    dataset : Dataset
        Stand or test-stand dataset with ``current_cmd_mA``.
    setting : str, optional
        Only experiments whose name ends with this dither tag (e.g. ``50Hz_A``);
        the first experiment's tag when omitted.
    """
    from matplotlib.figure import Figure  # imported on use: simulation workers never draw

    fig = Figure(figsize=(7.5, 5), layout="constrained")  # no pyplot: no global backend
    ax = fig.subplots()
    tag = setting or "_".join(dataset[0].name.split("_")[1:])
    for trace in dataset:
        if not trace.name.endswith(tag) or not trace.has("current_cmd_mA"):
            continue
        p = dither_period_mean(trace.get("clutch_pressure_bar"), dither_period_samples(trace))
        ax.plot(
            trace.get("current_cmd_mA"),
            p,
            lw=0.9,
            color=_COLORS.get(trace.ramp),
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
