"""Hydraulic effects: flow forces, leakage, supply droop, entrained air, accumulator springs."""

from __future__ import annotations

import math

from ..assembly import Assembly
from ..components.base import param
from ..components.fluid import FLUID_NODES
from ..smooth import smooth_max0
from .base import Effect

__all__ = [
    "AccumulatorSpringNonlinearity",
    "AirEntrainment",
    "FlowForce",
    "SpoolLeakage",
    "SupplyDroop",
]

#: Jet angle of a sharp-edged spool port (rad).
JET_ANGLE = math.radians(69.0)


class FlowForce(Effect):
    """Steady flow (jet) force on the regulator spool, closing the metering edges."""

    name = "flow_force"
    description = "steady-state flow (Bernoulli) force on the regulator spool"
    signature = "pressure deficit growing with flow: during fills (|dI/dt|) and at high Δp"
    PARAMETERS = (
        param(
            "jet", "kappa", "-", 1.0, 0.0, 3.0, "flow-force coefficient (1 = ideal jet)", "linear"
        ),
    )
    STRENGTH = ("jet_kappa",)

    def apply(self, asm: Assembly) -> None:
        def force(a):
            k = 2.0 * a["Cd"] * math.cos(JET_ANGLE) * a.p("jet_kappa")
            dp_in = a["p_supply"] - a.x("p_c")
            dp_out = a.x("p_c") - a["p_prime"]
            return -k * (a["A_reg_in"] * dp_in + a["A_reg_out"] * dp_out)

        asm.add_term("F_reg", force)


class SpoolLeakage(Effect):
    """Extra laminar leakage from the clutch to exhaust (worn bore, clearance)."""

    name = "spool_leakage"
    description = "laminar leakage clutch → exhaust past the regulator lands"
    signature = "pressure deficit proportional to pressure level; larger when hot (thin oil)"
    PARAMETERS = (
        param("leak", "G", "mm³/(s·bar)", 300.0, 0.0, 5000.0, "leakage conductance", "linear"),
    )
    STRENGTH = ("leak_G",)

    def apply(self, asm: Assembly) -> None:
        asm.add_term(
            "Q_clutch_extra",
            lambda a: -a.p("leak_G") / a["visc_ratio"] * (a.x("p_c") - a["p_prime"]),
        )


class SupplyDroop(Effect):
    """A supply restriction in series with the regulator's inlet edge (line-pressure coupling).

    Two orifices in series split the line-to-clutch drop in the ratio of their
    squared areas: ``p_supply = p_line − (p_line − p_c)·(A_in r)² / (1 + (A_in r)²)``
    with ``r = 1/A_supply``; at ``r = 0`` the supply is stiff.
    """

    name = "supply_droop"
    description = "line-pressure coupling: supply droop with regulator inflow"
    signature = "deficit during fills (dI/dt > 0) and at the latch snap; follows line pressure"
    PARAMETERS = (
        param(
            "sup", "r", "1/mm²", 0.15, 0.0, 5.0, "inverse area of the supply restriction", "linear"
        ),
    )
    STRENGTH = ("sup_r",)

    def apply(self, asm: Assembly) -> None:
        def wrap(a, prev):
            ar2 = (a["A_reg_in"] * a.p("sup_r")) ** 2
            return prev - (a["p_line"] - a.x("p_c")) * ar2 / (1.0 + ar2)

        asm.wrap("p_supply", wrap)


class AirEntrainment(Effect):
    """Entrained air: the bulk modulus falls at low pressure (isentropic gas fraction)."""

    name = "air_entrainment"
    description = "pressure-dependent bulk modulus from entrained air"
    signature = "slow pressure rise and lag at low pressure; rate-dependent near the fill"
    PARAMETERS = (
        param("air", "alpha", "%", 0.5, 0.0, 5.0, "air volume fraction at atmosphere", "linear"),
    )
    STRENGTH = ("air_alpha",)
    P_ATM = 1.013e5
    POLYTROPIC = 1.4

    def apply(self, asm: Assembly) -> None:
        for node in FLUID_NODES:

            def wrap(a, prev, node=node):
                p_abs = smooth_max0(a.x(node) + self.P_ATM, 2e4) + 1e4
                alpha = a.p("air_alpha")
                frac = alpha * (self.P_ATM / p_abs) ** (1.0 / self.POLYTROPIC)
                return 1.0 / ((1.0 - frac) / prev + frac / (self.POLYTROPIC * p_abs))

            asm.wrap(f"beta:{node}", wrap)


class AccumulatorSpringNonlinearity(Effect):
    """Progressive accumulator springs ``F = k s (1 + κ s/stroke)``."""

    name = "accumulator_spring_nonlinearity"
    description = "progressive (nonlinear) accumulator springs"
    signature = "gain change with pressure level; lag that varies along the stroke"
    PARAMETERS = (
        param("accnl", "kappa_v", "-", 0.4, 0.0, 2.0, "VFS accumulator progression", "linear"),
        param("accnl", "kappa_c", "-", 0.4, 0.0, 2.0, "clutch accumulator progression", "linear"),
    )
    STRENGTH = ("accnl_kappa_v", "accnl_kappa_c")

    def apply(self, asm: Assembly) -> None:
        asm.wrap("acc_kappa:vacc", lambda a, prev: prev + a.p("accnl_kappa_v"))
        asm.wrap("acc_kappa:cacc", lambda a, prev: prev + a.p("accnl_kappa_c"))
