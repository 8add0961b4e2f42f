"""Oil temperature: viscosity dependence of damping and leakage."""

from __future__ import annotations

import casadi as ca

from ..assembly import Assembly
from ..components.base import param
from .base import Effect

__all__ = ["OilTemperature"]


class OilTemperature(Effect):
    """Viscosity ``μ(T) = μ_ref · exp(−b (T − T_ref))`` scales damping (∝ μ) and leakage (∝ 1/μ)."""

    name = "oil_temperature"
    description = "oil-temperature / viscosity dependence of damping and leakage"
    signature = "residual that follows oil temperature; leakage deficit grows when hot"
    PARAMETERS = (
        param("temp", "b", "1/K", 0.03, 0.0, 0.1, "viscosity-temperature coefficient", "linear"),
        param(
            "temp",
            "T_ref",
            "°C",
            40.0,
            -20.0,
            120.0,
            "reference temperature of the defaults",
            "linear",
        ),
    )
    STRENGTH = ("temp_b",)

    def apply(self, asm: Assembly) -> None:
        asm.wrap(
            "visc_ratio",
            lambda a, prev: prev * ca.exp(-a.p("temp_b") * (a["T_oil"] - a.p("temp_T_ref"))),
        )
