"""Latch valve: differential-area snap action that exhausts the regulator feedback."""

from __future__ import annotations

import math

from ..assembly import Assembly, StateSpec
from ..smooth import logistic, smooth_max0
from .base import Component, param
from .fluid import flow

__all__ = ["LatchValve", "latch_thresholds"]

_C = "latch"


def latch_thresholds(values) -> tuple[float, float]:
    """Ideal latch-on and latch-off pilot pressures (bar) from parameter values.

    ``p_on = F0 / A1`` (closed: pilot acts on the small area), ``p_off = (F0 + k·s) / A2``
    (open: pilot acts on the full area, spring compressed by the stroke).

    Parameters
    ----------
    values : mapping
        Parameter values in engineering units (``latch_d1`` mm, ``latch_F0`` N …).
        With the ``latch_free_thresholds`` law on (``lthr_p_on``, ``lthr_p_off`` bar
        among the values), those are the thresholds.
    """
    if "lthr_p_on" in values and "lthr_p_off" in values:
        return float(values["lthr_p_on"]), float(values["lthr_p_off"])
    a1 = math.pi / 4.0 * (values["latch_d1"] * 1e-3) ** 2
    a2 = math.pi / 4.0 * (values["latch_d2"] * 1e-3) ** 2
    p_on = values["latch_F0"] / a1 / 1e5
    p_off = (values["latch_F0"] + values["latch_k"] * 1e3 * values["latch_stroke"] * 1e-3) / a2
    return p_on, p_off / 1e5


class LatchValve(Component):
    """Two-position latch valve with differential-area hysteresis.

    Latch opening ``λ ∈ (0, 1)``: ``τ dλ/dt = σ(F_net(λ)/F_w) − λ`` with
    ``F_net = p_a (A1 + (A2 − A1) λ) − F0 − k·s·λ``: bistable, snaps open at
    ``p_on = F0/A1`` and closes at ``p_off = (F0 + k s)/A2 < p_on``. The feedback
    exhaust opens after an overlap (a fraction of the stroke), so the hydraulic
    latch follows the mechanical snap, not its first micrometres.
    """

    name = _C
    description = "latch valve"
    PARAMETERS = (
        param(_C, "d1", "mm", 6.0, 3.0, 12.0, "pilot diameter, closed"),
        param(_C, "d2", "mm", 7.0, 3.5, 14.0, "pilot diameter, open (differential area)"),
        param(_C, "F0", "N", 27.7, 2.0, 100.0, "spring preload"),
        param(_C, "k", "N/mm", 2.0, 0.2, 20.0, "spring rate"),
        param(_C, "stroke", "mm", 2.0, 0.5, 5.0, "valve stroke"),
        param(_C, "F_w", "N", 0.4, 0.05, 2.0, "force width of the smooth snap"),
        param(_C, "tau", "ms", 5.0, 0.5, 50.0, "switching time constant"),
        param(_C, "d_exh", "mm", 2.5, 0.5, 5.0, "feedback exhaust passage when latched"),
        param(_C, "overlap", "-", 0.3, 0.05, 0.8, "exhaust overlap, fraction of the stroke"),
    )

    def build(self, asm: Assembly) -> None:
        lam = asm.state(StateSpec("latch", "-", 0.0, "latch valve opening (0 closed, 1 open)", _C))

        def f_net(a):
            a1 = math.pi / 4.0 * a.p("latch_d1") ** 2
            a2 = math.pi / 4.0 * a.p("latch_d2") ** 2
            return (
                a.x("p_a") * (a1 + (a2 - a1) * lam)
                - a.p("latch_F0")
                - a.p("latch_k") * a.p("latch_stroke") * lam
            )

        asm.define("latch_F_net", f_net, "N")
        asm.define(
            "der:latch",
            lambda a: (logistic(a["latch_F_net"] / a.p("latch_F_w")) - lam) / a.p("latch_tau"),
            "1/s",
        )
        asm.define(
            "V_latch_rate",
            lambda a: math.pi / 4.0 * a.p("latch_d1") ** 2 * a.p("latch_stroke") * a["der:latch"],
            "m³/s",
        )

        def q_exh(a):
            ov = a.p("latch_overlap")
            opening = smooth_max0(lam - ov, 0.005) / (1.0 - ov)
            area = math.pi / 4.0 * a.p("latch_d_exh") ** 2 * opening
            return flow(a, area, a.x("p_fb") - a["p_prime"])

        asm.define("Q_latch_exh", q_exh, "m³/s")
