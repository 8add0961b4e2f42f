"""Hydraulic fluid (ATF) properties and boundary pressures."""

from __future__ import annotations

from ..assembly import Assembly
from ..smooth import orifice_flow
from .base import Component, param

__all__ = ["FLUID_NODES", "Fluid", "flow"]

#: Hydraulic nodes (state names) whose bulk modulus is signal ``beta:<node>``.
FLUID_NODES = ("p_vo", "p_a", "p_c", "p_fb")

_C = "fluid"


class Fluid(Component):
    """ATF: density, bulk modulus, discharge coefficient; line / prime / temperature inputs.

    Defines ``rho`` (kg/m³), ``Cd`` (-), ``p_cr`` (Pa), ``beta:<node>`` (Pa) for each
    hydraulic node, ``p_line``, ``p_prime`` (Pa, gauge) and ``T_oil`` (°C).
    """

    name = _C
    description = "automatic transmission fluid and supply boundary conditions"
    PARAMETERS = (
        param(_C, "rho", "kg/m³", 850.0, 800.0, 900.0, "oil density"),
        param(_C, "beta", "GPa", 1.5, 0.5, 2.0, "effective bulk modulus of the oil"),
        param(_C, "Cd", "-", 0.65, 0.55, 0.75, "orifice discharge coefficient"),
        param(
            _C,
            "p_cr",
            "bar",
            0.1,
            0.01,
            1.0,
            "laminar/turbulent transition pressure of the regularized orifice law",
        ),
    )

    def build(self, asm: Assembly) -> None:
        asm.define("rho", lambda a: a.p("fluid_rho"), "kg/m³")
        asm.define("Cd", lambda a: a.p("fluid_Cd"), "-")
        asm.define("p_cr", lambda a: a.p("fluid_p_cr"), "Pa")
        for node in FLUID_NODES:
            asm.define(f"beta:{node}", lambda a: a.p("fluid_beta"), "Pa")
        asm.define("p_line", lambda a: a.u["line_pressure_bar"] * 1e5, "Pa")
        asm.define("p_prime", lambda a: a.u["prime_pressure_bar"] * 1e5, "Pa")
        asm.define("T_oil", lambda a: a.u["oil_temp_C"], "°C")
        # Viscosity ratio mu(T)/mu(T_ref): 1 in the base model, temperature effect wraps it.
        asm.define("visc_ratio", lambda a: 1.0, "-")


def flow(asm: Assembly, area, dp):
    """Regularized orifice flow (m³/s) through ``area`` (m²) under ``dp`` (Pa)."""
    return orifice_flow(asm["Cd"], area, dp, asm["rho"], asm["p_cr"])
