"""Spring-piston accumulators as a pressure-dependent compliance (quasi-static piston)."""

from __future__ import annotations

import math

from ..assembly import Assembly
from ..smooth import smooth_max0, smooth_window
from .base import param

__all__ = [
    "accumulator_compliance",
    "accumulator_parameters",
    "declare_accumulator_node",
    "node_compliance",
]


def accumulator_parameters(
    prefix: str,
    d_mm: float,
    k_N_mm: float,
    p0_bar: float,
    stroke_mm: float,
    what: str,
    volume_cm3: float,
    line: str,
):
    """Parameters of spring-piston accumulator ``prefix`` and the oil volume (cm³) of its node."""
    return (
        param(
            prefix, "V", "cm³", volume_cm3, 0.1 * volume_cm3, 6.0 * volume_cm3, f"{line} oil volume"
        ),
        param(prefix, "d", "mm", d_mm, 0.4 * d_mm, 2.5 * d_mm, f"{what} piston diameter"),
        param(prefix, "k", "N/mm", k_N_mm, 0.2 * k_N_mm, 5.0 * k_N_mm, f"{what} spring rate"),
        param(prefix, "p0", "bar", p0_bar, 0.1, 10.0, f"{what} cracking (preload) pressure"),
        param(
            prefix,
            "stroke",
            "mm",
            stroke_mm,
            0.2 * stroke_mm,
            3.0 * stroke_mm,
            f"{what} piston stroke",
        ),
    )


def accumulator_compliance(asm: Assembly, prefix: str, p):
    """Compliance dV/dp (m³/Pa) of accumulator ``prefix`` at gauge pressure ``p`` (Pa).

    While stroking the compliance is ``A²/k(s)``; outside the stroke (below the
    cracking pressure, or bottomed out) it vanishes, with smooth stops 0.3 bar wide.
    The spring is ``F = k·s·(1 + κ·s/stroke)``; κ is signal ``acc_kappa:<prefix>``
    (0 in the base model: a linear spring; the spring-nonlinearity effect sets it).
    """
    area = math.pi / 4.0 * asm.p(f"{prefix}_d") ** 2
    k = asm.p(f"{prefix}_k")
    p0 = asm.p(f"{prefix}_p0")
    stroke = asm.p(f"{prefix}_stroke")
    kappa = asm[f"acc_kappa:{prefix}"]
    dp = smooth_max0(p - p0, 1e3)
    # s solves k·s + κ·k·s²/stroke = A·dp, written without division by κ.
    s = 2.0 * area * dp / (k + (k * k + 4.0 * kappa * k * area * dp / stroke) ** 0.5)
    p_full = p0 + k * stroke * (1.0 + kappa) / area
    return area**2 / (k * (1.0 + 2.0 * kappa * s / stroke)) * smooth_window(p, p0, p_full, 0.3e5)


def declare_accumulator_node(asm: Assembly, prefix: str) -> None:
    """Define the accumulator's spring progression ``acc_kappa:<prefix>`` (0: linear spring)."""
    asm.define(f"acc_kappa:{prefix}", lambda a: 0.0, "-")


def node_compliance(asm: Assembly, prefix: str, node: str, p):
    """Compliance (m³/Pa) of hydraulic node ``node``: oil ``V/β(p)`` plus accumulator ``prefix``."""
    return asm.p(f"{prefix}_V") / asm[f"beta:{node}"] + accumulator_compliance(asm, prefix, p)
