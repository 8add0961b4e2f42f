"""Solenoid current: the dithered current command and the current control loop."""

from __future__ import annotations

import math

import casadi as ca

from ..assembly import Assembly, StateSpec
from ..smooth import smooth_max0
from .base import Component, param

__all__ = ["CurrentDriver", "dither_waveform"]

_C = "drv"


def dither_waveform(phase, w_sine, w_triangle, w_square):
    """Unit-amplitude dither waveform at ``phase`` (cycles), a weighted sum of shapes.

    Triangle and square are smooth approximations (peak rounding < 0.1 %, edge
    width ≈ 1 % of the period).
    """
    s = ca.sin(2.0 * math.pi * phase)
    tri = (2.0 / math.pi) * ca.asin(0.999 * s) / (2.0 / math.pi * math.asin(0.999))
    sq = ca.tanh(s / 0.03)
    return w_sine * s + w_triangle * tri + w_square * sq


class CurrentDriver(Component):
    """Current source of the VFS coil.

    ``drive="command"``: ``τ_i di/dt = i_cmd − i`` with
    ``i_cmd = max(0, I + A_d·w(2π f_d t))`` (PWM drivers cannot reverse current).
    ``drive="measured"``: the coil current is the measured current input.
    Defines ``i_coil`` (A) and ``di_coil`` (A/s).
    """

    name = _C
    description = "PWM current driver with dither and current loop"
    PARAMETERS = (param(_C, "tau_i", "ms", 1.0, 0.1, 5.0, "current-loop time constant"),)

    def build(self, asm: Assembly) -> None:
        if asm.drive == "command":
            i = asm.state(StateSpec("i", "mA", 0.0, "coil current", _C))

            def i_cmd(a):
                w = dither_waveform(
                    a.u["dither_phase"], a.u["wave_sine"], a.u["wave_triangle"], a.u["wave_square"]
                )
                raw = a.u["current_nom_mA"] + a.u["dither_amp_mA"] * w
                return smooth_max0(raw, 1.0) * 1e-3

            asm.define("i_cmd", i_cmd, "A")
            asm.define("i_coil", lambda a: i, "A")
            asm.define("di_coil", lambda a: (a["i_cmd"] - i) / a.p("drv_tau_i"), "A/s")
            asm.define("der:i", lambda a: a["di_coil"], "A/s")
        else:
            asm.define("i_coil", lambda a: a.u["current_meas_mA"] * 1e-3, "A")
            asm.define("di_coil", lambda a: a.u["current_meas_rate_mA_s"] * 1e-3, "A/s")
