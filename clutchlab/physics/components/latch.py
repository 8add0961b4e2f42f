"""Latch valve: differential-area snap action that exhausts the regulator feedback."""

from __future__ import annotations

import math

from ..assembly import Assembly, StateSpec
from ..smooth import logistic, smooth_max0, smooth_max0_slope
from .base import Component, param
from .fluid import flow

__all__ = ["LatchValve", "latch_snap_problem", "latch_thresholds"]

_C = "latch"

#: Rounding (latch opening, -) of the port-opening corner at the overlap.
_PORT_EPS = 0.005


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


def latch_snap_problem(values) -> str | None:
    """Why the latch valve of ``values`` cannot latch, or None when it snaps.

    The valve snaps (and latches) only when its latch-off pressure lies below its latch-on
    pressure, ``p_off < p_on``: then the force gained as it opens (the pilot pressure on the
    differential area ``A2 − A1``) exceeds the spring force it adds (``k·s``). With
    ``p_off ≥ p_on`` — ``latch_d2 ≤ latch_d1`` (no differential area), or a spring too stiff
    for the area step — it opens gradually and closes at the same pressure: no snap, no
    hysteresis, no latched state. The bounds of the single parameters cannot exclude this.

    Parameters
    ----------
    values : mapping
        Parameter values in engineering units (``latch_d1``, ``latch_d2`` mm, ``latch_F0``
        N, ``latch_k`` N/mm, ``latch_stroke`` mm; ``lthr_p_on``, ``lthr_p_off`` bar with the
        ``latch_free_thresholds`` law; ``ldrift_dp_on``, ``ldrift_dp_off`` bar with the
        ``latch_threshold_drift`` effect).

    Returns
    -------
    str or None
        The problem, naming ``latch_d1`` and ``latch_d2`` (mm) and both thresholds (bar);
        None when the valve latches or ``values`` has no latch valve.
    """
    free = "lthr_p_on" in values and "lthr_p_off" in values  # the law retires F0 and k
    needed = ("latch_d1", "latch_d2") + (() if free else ("latch_F0", "latch_k", "latch_stroke"))
    if not all(n in values for n in needed):
        return None
    p_on, p_off = latch_thresholds(values)
    p_on += float(values.get("ldrift_dp_on", 0.0))
    p_off += float(values.get("ldrift_dp_off", 0.0))
    if p_off < p_on:
        return None
    d1, d2 = float(values["latch_d1"]), float(values["latch_d2"])
    if free:
        why = "the latch-off pressure lthr_p_off is not below the latch-on pressure lthr_p_on"
    elif d2 <= d1:
        why = f"latch_d2 = {d2:.12g} mm ≤ latch_d1 = {d1:.12g} mm leaves no differential area"
    else:
        why = (
            f"latch_d2 = {d2:.12g} mm > latch_d1 = {d1:.12g} mm, but the differential area is too "
            f"small for the spring (latch_k·latch_stroke = "
            f"{float(values['latch_k']) * float(values['latch_stroke']):g} N)"
        )
    return (
        f"the latch valve cannot latch: {why}, so it would close at p_off = {p_off:.3g} bar, "
        f"not below where it opens, p_on = {p_on:.3g} bar: it opens and closes gradually, "
        "without snap action, hysteresis or a latched state. A latching valve needs "
        "p_off < p_on (latch_d2 > latch_d1 and (F0 + k·stroke)/A2 < F0/A1); a non-latching "
        "valve may be intended (a design sweep), so the set is accepted"
    )


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

        # the pressure on the latch's pilot faces: the VFS accumulator's (a flexible law
        # may lag it, latch_pilot_lag)
        asm.define("p_latch_pilot", lambda a: a.x("p_a"), "Pa")

        def f_net(a):
            a1 = math.pi / 4.0 * a.p("latch_d1") ** 2
            a2 = math.pi / 4.0 * a.p("latch_d2") ** 2
            return (
                a["p_latch_pilot"] * (a1 + (a2 - a1) * lam)
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

        # The latched port's opening (0–1): it opens after the overlap, so the hydraulic
        # latch follows the mechanical snap (a flexible law may switch another port with it).
        asm.define(
            "latch_port_opening",
            lambda a: (
                smooth_max0(lam - a.p("latch_overlap"), _PORT_EPS) / (1.0 - a.p("latch_overlap"))
            ),
            "-",
        )
        asm.define(
            "latch_port_opening_rate",
            lambda a: (
                smooth_max0_slope(lam - a.p("latch_overlap"), _PORT_EPS)
                / (1.0 - a.p("latch_overlap"))
                * a["der:latch"]
            ),
            "1/s",
        )

        def q_exh(a):
            area = math.pi / 4.0 * a.p("latch_d_exh") ** 2 * a["latch_port_opening"]
            return flow(a, area, a.x("p_fb") - a["p_prime"])

        asm.define("Q_latch_exh", q_exh, "m³/s")
