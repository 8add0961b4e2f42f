"""Flexible component laws: shapes the datasheet form of a component cannot take.

Each is an :class:`~clutchlab.physics.effects.base.Effect` (switched on by name like
the library effects) whose *identity* setting — every strength parameter at its
default of zero, or the latch thresholds at the datasheet latch's — gives exactly
today's model, so a fit starts from the datasheet model and moves away only as far
as the training data ask. All forms are smooth (``tanh`` / logistic; no ``if_else``).

- :class:`MonotoneForceCorrection` (``vfs_force_monotone``): the VFS magnetic force
  curve plus a non-negative sum of logistic steps at fixed current knots: any
  monotone static characteristic (saturating, quadratic, kinked) within the span of
  the knots, monotone for every admissible parameter value.
- :class:`PlayHysteresis` (``vfs_play_hysteresis``): a Prandtl–Ishlinskii operator —
  a weighted sum of smooth play (backlash) operators of the coil current with fixed
  widths — subtracted from the magnetic force: rate-independent hysteresis of any
  convex loop shape, minor loops under dither.
- :class:`FreeLatchThresholds` (``latch_free_thresholds``): the latch-on and
  latch-off pilot pressures as parameters (bar) in place of the spring preload and
  rate, so the latch hysteresis is no longer tied to the valve's area ratio.
- :class:`LatchLineSelect` (``latch_line_select``): the latch valve as a selector of the
  clutch feed — latched, the clutch port sees line pressure while the regulator keeps
  regulating its own output — in place of the datasheet valve's feedback exhaust.
- :class:`RegulatorPilotLag` (``reg_pilot_lag``): a lag of the pilot pressure at the
  regulator alone.
- :class:`LatchPilotLag` (``latch_pilot_lag``): a lag of the pilot pressure at the latch
  valve alone — with the regulator's, the two branches each have a lag of their own.
- :class:`LatchOnLag` (``latch_on_lag``): the latch-on delayed in proportion to the rising
  command's rate, the release not (a latch that trips on a lagging pressure).
- :class:`LatchDitherBand` (``latch_dither_band``): a latch hysteresis band that widens or
  narrows with the dither amplitude and frequency (a latch that needs its pilot beyond a
  threshold for a dwell time, or that filters the dither, switches where the model's
  crest-tripping latch does not).
- :class:`LatchRateBand` (``latch_rate_band``): a latch band that changes with the ramp
  rate, by an amount that depends on the dither (a dwell latch).
- :class:`LatchLineThreshold` (``latch_line_threshold``): latch thresholds that move with
  line pressure (a latch valve balanced against line rather than a spring alone).
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from ...data import LINE_PRESSURE_BAR
from ..assembly import Assembly, StateSpec
from ..components.base import param
from ..components.latch import LatchValve, latch_thresholds
from ..smooth import logistic
from .base import Effect

__all__ = [
    "FORCE_KNOTS_MA",
    "PLAY_WIDTHS_MA",
    "FreeLatchThresholds",
    "LatchDitherBand",
    "LatchLineSelect",
    "LatchLineThreshold",
    "LatchOnLag",
    "LatchPilotLag",
    "LatchRateBand",
    "MonotoneForceCorrection",
    "PlayHysteresis",
    "RegulatorPilotLag",
    "dither_band_terms",
    "rate_band_terms",
    "switched_on",
]

#: Current knots (mA) of the monotone force correction, and the width (mA) of each step.
FORCE_KNOTS_MA: tuple[float, ...] = (150.0, 350.0, 550.0, 750.0)
FORCE_STEP_WIDTH_MA = 70.0

#: Widths (mA) of the play operators of the Prandtl–Ishlinskii hysteresis.
PLAY_WIDTHS_MA: tuple[float, ...] = (15.0, 50.0, 150.0)

#: Scale (A/s) of the smooth sign of the current rate in the play operators.
_RATE_SIGN_SCALE = 1e-2


class MonotoneForceCorrection(Effect):
    """Monotone correction of the VFS magnetic force curve.

    ``F_mag(i) + Σ_k d_k · σ((i − c_k)/w)`` with ``σ`` the logistic function, knots
    ``c_k`` = :data:`FORCE_KNOTS_MA`, step width ``w`` = ``mspl_w`` and step heights
    ``d_k ≥ 0`` (N). Every term is non-decreasing in ``i``, so the force curve stays
    monotone for every admissible value; with the free gain, knee and preload of the
    base curve it represents saturating, progressive and kinked characteristics.
    All ``d_k = 0`` (the default) is exactly the datasheet curve.
    """

    name = "vfs_force_monotone"
    description = "monotone (sum-of-logistic-steps) correction of the VFS force curve"
    signature = (
        "residual that is a smooth function of the current level, the same on rising and "
        "falling ramps and at every ramp rate"
    )
    PARAMETERS = (
        *(
            param("mspl", f"d{k + 1}", "N", 0.0, 0.0, 6.0, f"force step at {c:g} mA", "linear")
            for k, c in enumerate(FORCE_KNOTS_MA)
        ),
        param("mspl", "w", "mA", FORCE_STEP_WIDTH_MA, 20.0, 200.0, "width of each force step"),
    )
    STRENGTH = tuple(f"mspl_d{k + 1}" for k in range(len(FORCE_KNOTS_MA)))

    def apply(self, asm: Assembly) -> None:
        def steps(a):
            i, w = a["i_coil"], a.p("mspl_w")
            return [logistic((i - c * 1e-3) / w) for c in FORCE_KNOTS_MA]

        def force(a, prev):
            return prev + sum(a.p(n) * s for n, s in zip(self.STRENGTH, steps(a), strict=True))

        def rate(a, prev):
            w = a.p("mspl_w")
            slope = sum(
                a.p(n) * s * (1.0 - s) / w for n, s in zip(self.STRENGTH, steps(a), strict=True)
            )
            return prev + slope * a["di_coil"]

        asm.wrap("F_mag", force)
        asm.wrap("dF_mag", rate)


class PlayHysteresis(Effect):
    """Prandtl–Ishlinskii hysteresis of the VFS force: a weighted sum of play operators.

    Each operator ``j`` of width ``r_j`` (:data:`PLAY_WIDTHS_MA`) has a normalized
    play state ``h_j ∈ [−1, 1]`` (smooth: ``dh_j/dt = (di/dt / r_j)(1 − h_j tanh(di/dt /
    ε))``, the play's ±1 stops reached asymptotically over a travel of about ``r_j``)
    and the force is ``F_mag − Σ_j H_j h_j``: less force rising, more falling. The
    weights ``H_j ≥ 0`` (N) shape the loop — narrow operators give a sharp loop corner,
    wide ones a rounded one — and dither drives minor loops that shrink the loop.
    All ``H_j = 0`` (the default) is exactly today's force; one operator alone is the
    library's ``vfs_magnetic_hysteresis``.
    """

    name = "vfs_play_hysteresis"
    description = "Prandtl–Ishlinskii (sum of play operators) hysteresis of the VFS force"
    signature = (
        "offset of opposite sign on rising and falling current whose shape varies along "
        "the reversal; independent of ramp rate, reduced by dither"
    )
    PARAMETERS = tuple(
        p
        for j, r in enumerate(PLAY_WIDTHS_MA)
        for p in (
            param(
                "play",
                f"H{j + 1}",
                "N",
                0.0,
                0.0,
                3.0,
                f"weight of play operator {j + 1}",
                "linear",
            ),
            param("play", f"r{j + 1}", "mA", r, 2.0, 400.0, f"width of play operator {j + 1}"),
        )
    )
    STRENGTH = tuple(f"play_H{j + 1}" for j in range(len(PLAY_WIDTHS_MA)))

    def apply(self, asm: Assembly) -> None:
        states = []
        for j in range(len(PLAY_WIDTHS_MA)):
            spec = StateSpec(f"h_play{j + 1}", "-", 0.0, f"play operator {j + 1} state", self.name)
            h = asm.state(spec)
            states.append(h)

            def dh(a, h=h, j=j):
                di = a["di_coil"]
                return di / a.p(f"play_r{j + 1}") * (1.0 - h * ca.tanh(di / _RATE_SIGN_SCALE))

            asm.define(f"der:h_play{j + 1}", dh, "1/s")

        def force(a, prev):
            return prev - sum(a.p(f"play_H{j + 1}") * h for j, h in enumerate(states))

        def rate(a, prev):
            return prev - sum(
                a.p(f"play_H{j + 1}") * a[f"der:h_play{j + 1}"] for j in range(len(states))
            )

        asm.wrap("F_mag", force)
        asm.wrap("dF_mag", rate)


def _datasheet_thresholds() -> tuple[float, float]:
    """Latch-on / latch-off pilot pressures (bar) of the datasheet latch valve."""
    return latch_thresholds({p.name: p.default for p in LatchValve.PARAMETERS})


_P_ON, _P_OFF = _datasheet_thresholds()


class FreeLatchThresholds(Effect):
    """Latch-on and latch-off pilot pressures as parameters of their own.

    Replaces the latch force ``F_net = (1 − λ)(A1 p_a − F0) + λ(A2 p_a − F0 − k s)`` by
    ``(1 − λ) A1 (p_a − p_on) + λ A2 (p_a − p_off)`` — the same law, written in its two
    thresholds — and retires the spring preload ``latch_F0`` and rate ``latch_k``,
    which then no longer act. The datasheet valve ties ``p_off`` to at least
    ``A1/A2 · p_on`` (the area ratio); here the two are free. The defaults are the
    datasheet valve's thresholds, so the effect at its defaults is today's model.
    """

    name = "latch_free_thresholds"
    description = "latch-on / latch-off pressures as free parameters (no area-ratio tie)"
    signature = "large residual in the current band between modelled and true latch-on/off"
    PARAMETERS = (
        param("lthr", "p_on", "bar", _P_ON, 1.0, 17.0, "latch-on pilot pressure"),
        param("lthr", "p_off", "bar", _P_OFF, 0.5, 17.0, "latch-off pilot pressure"),
    )
    STRENGTH = ()
    FIT = ("lthr_p_on", "lthr_p_off")
    #: Base-model parameters this law retires (a fit must not free them).
    REPLACES = ("latch_F0", "latch_k")

    def apply(self, asm: Assembly) -> None:
        def f_net(a):
            a1 = math.pi / 4.0 * a.p("latch_d1") ** 2
            a2 = math.pi / 4.0 * a.p("latch_d2") ** 2
            lam, p = a.x("latch"), a["p_latch_pilot"]
            return (1.0 - lam) * a1 * (p - a.p("lthr_p_on")) + lam * a2 * (p - a.p("lthr_p_off"))

        asm.redefine("latch_F_net", f_net)
        for name in self.REPLACES:
            asm.retire_parameter(name)


class LatchLineSelect(Effect):
    """The latch valve selects the clutch feed: regulator output, or line pressure.

    The datasheet valve latches by exhausting the regulator's feedback chamber: the
    regulator spool then runs to its stop and fills the clutch from line, and on release
    the chamber must refill and the spool travel back before the clutch drains to the
    regulated pressure — a release slower than the snap-on, which moves the release
    further with the ramp rate than the snap-on. Many valve bodies switch the clutch port
    instead: latched, the clutch is fed from line through the latch valve and the
    regulator, cut off, keeps regulating its own output, so on release the port returns
    to the regulated pressure within the valve's stroke.

    With weight ``w`` the port pressure is ``p_c + w·s(λ)·(p_line − p_c)`` (``s`` the
    latch's port opening, 0–1, after its overlap) and the feedback exhaust flow is
    scaled by ``1 − w``. ``w = 0`` (the default) is exactly today's model; a fit that
    switches the law on holds ``w = 1`` (no parameter of its own: the valve's stroke time
    ``latch_tau`` and overlap set the switching). The rate of the port pressure neglects
    the line pressure's own rate (it enters sensor lags only).
    """

    name = "latch_line_select"
    description = "latch valve switching the clutch port to line (regulator keeps regulating)"
    signature = (
        "latch release later than the snap-on by a delay that grows with the ramp rate "
        "(the released clutch drains slowly to the regulated pressure)"
    )
    PARAMETERS = (
        param("lsel", "w", "-", 0.0, 0.0, 1.0, "weight of the line-select latch port", "linear"),
    )
    STRENGTH = ("lsel_w",)
    FIT = ()
    #: A fit holds the weight on (:func:`switched_on`).
    HELD_SWITCH = True

    def apply(self, asm: Assembly) -> None:
        def gain(a):
            return a.p("lsel_w") * a["latch_port_opening"]

        def rate(a):
            return a.p("lsel_w") * a["latch_port_opening_rate"]

        asm.wrap("Q_latch_exh", lambda a, prev: (1.0 - a.p("lsel_w")) * prev)
        asm.tap("p_clutch_port", "p_clutch_port_in:lsel")
        asm.wrap(
            "p_clutch_port",
            lambda a, prev: prev + gain(a) * (a["p_line"] - prev),
        )
        asm.wrap(
            "dp_clutch_port",
            lambda a, prev: (
                (1.0 - gain(a)) * prev + rate(a) * (a["p_line"] - a["p_clutch_port_in:lsel"])
            ),
        )


def _pilot_lag(asm: Assembly, pilot: str, state: StateSpec, prefix: str) -> None:
    """Blend signal ``pilot`` towards a first-order lag of the accumulator pressure.

    ``pilot + w (q − pilot)`` with ``τ dq/dt = p_a − q``; ``w`` and ``τ`` are the
    parameters ``{prefix}_w`` (-) and ``{prefix}_tau`` (ms), ``q`` the new state.
    """
    q = asm.state(state)
    w, tau = f"{prefix}_w", f"{prefix}_tau"
    asm.define(f"der:{state.name}", lambda a: (a.x("p_a") - q) / a.p(tau), "Pa/s")
    asm.wrap(pilot, lambda a, prev: prev + a.p(w) * (q - prev))


class RegulatorPilotLag(Effect):
    """A first-order lag of the pilot pressure on the regulator spool's pilot face alone.

    The regulator sees ``p_r = p_a + w (q − p_a)`` with ``τ dq/dt = p_a − q``; the latch
    valve still sees ``p_a``. In the datasheet circuit one lag (the VFS accumulator
    orifice) sets both the rate-dependent width of the regulated hysteresis band and
    the delay of the latch snap behind the current; a circuit whose clutch fills
    through a slower path than its latch pilot (a damping orifice, a clutch
    accumulator, entrained air) has a wider band at fast ramps than that one lag can
    give without moving the latch currents. ``w = 0`` (the default) is exactly today's
    model; a fit that switches the law on holds ``w = 1`` and frees ``τ``.

    Known defect: the lag acts on all of ``p_a``, including the change the regulator
    spool's own displacement makes in it, i.e. it lags the pilot chamber's hydraulic
    spring, which is negative damping. With thin oil, a low prime pressure or an
    unbalanced start some parameter sets are unstable (a ``--regulator-lag auto`` fit on a
    zoo plant stopped with ``Error_In_Step_Computation``). The fix (tag
    ``stable-reg-pilot-lag``, commit c5c700a) is not landed: as the discovery's flexible
    alternative the stable law no longer matches sensor_lag and transport_delay on the
    default stand, and the demo then claims transport_delay and takes 1062 s (BENCHMARKS,
    session 20).
    """

    name = "reg_pilot_lag"
    description = "first-order lag of the pilot pressure at the regulator alone (not the latch)"
    signature = (
        "regulated branch lags the current more at fast ramps (band wider than the latch "
        "delay allows); latched plateau and latch currents unaffected"
    )
    PARAMETERS = (
        param("rlag", "w", "-", 0.0, 0.0, 1.0, "weight of the lagged pilot pressure", "linear"),
        param("rlag", "tau", "ms", 80.0, 2.0, 1000.0, "time constant of the regulator lag"),
    )
    STRENGTH = ("rlag_w",)
    FIT = ("rlag_tau",)
    #: A fit holds the weight on (:func:`switched_on`).
    HELD_SWITCH = True

    def apply(self, asm: Assembly) -> None:
        _pilot_lag(
            asm,
            "p_reg_pilot",
            StateSpec("p_rlag", "bar", 0.5, "lagged regulator pilot", self.name),
            "rlag",
        )


class LatchPilotLag(Effect):
    """A first-order lag of the pilot pressure on the latch valve's pilot faces alone.

    The latch sees ``p_l = p_a + w (q − p_a)`` with ``τ dq/dt = p_a − q``; the regulator
    still sees its own pilot pressure. The complement of :class:`RegulatorPilotLag`: a
    valve body whose latch pilot is fed through a damping orifice of its own snaps and
    releases later behind the current, the more so the faster the ramp, while the
    regulated branch is untouched. With both laws the regulated branch and the latch
    each have a lag of their own. ``w = 0`` (the default) is exactly today's model; a fit
    that switches the law on holds ``w = 1`` and frees ``τ``.

    Discovery offers it as a flexible alternative only to a model that already holds
    ``reg_pilot_lag`` (:attr:`ALTERNATIVE_AFTER`): without it, the regulator's lag is
    the one-parameter lag the candidates meet. The latch pilot's own flow (the valve's
    swept volume) is still drawn from the accumulator.
    """

    name = "latch_pilot_lag"
    description = "first-order lag of the pilot pressure at the latch valve alone"
    signature = (
        "latch snap and release lag the current more at fast ramps than the regulated "
        "branch does; regulated branch and latched plateau unaffected"
    )
    PARAMETERS = (
        param("llag", "w", "-", 0.0, 0.0, 1.0, "weight of the lagged latch pilot", "linear"),
        param("llag", "tau", "ms", 20.0, 1.0, 1000.0, "time constant of the latch pilot lag"),
    )
    STRENGTH = ("llag_w",)
    FIT = ("llag_tau",)
    #: A fit holds the weight on (:func:`switched_on`).
    HELD_SWITCH = True
    ALTERNATIVE_AFTER = ("reg_pilot_lag",)

    def apply(self, asm: Assembly) -> None:
        spec = StateSpec("p_llag", "bar", 0.5, "lagged latch pilot pressure", self.name)
        _pilot_lag(asm, "p_latch_pilot", spec, "llag")


def _command_rate(asm: Assembly, state: str, law: str):
    """Add a 50 ms filter of the commanded current (state ``state``, A) for law ``law``;
    returns ``rate(a)``: the command's ramp rate (mA/s) from it."""
    spec = StateSpec(state, "A", 0.0, "commanded current, 50 ms filter", law)
    filtered = asm.state(spec)

    def rate_mA_s(a):
        return (a.u["current_nom_mA"] * 1e-3 - filtered) / RATE_FILTER_S * 1e3

    asm.define(f"der:{state}", lambda a: rate_mA_s(a) * 1e-3, "A/s")
    return rate_mA_s


class LatchOnLag(Effect):
    """The latch-on delayed in proportion to the rising command's rate; the release not.

    The latch valve sees its pilot ``r R⁺ / 1000 mA/s`` lower (bar), ``R⁺`` the rising part
    of the commanded current's ramp rate (mA/s; a 50 ms filter state, as
    :class:`LatchRateBand`, and a smooth ``max(R, 0)``): on a rising ramp the latch snaps
    later by a current that grows with the rate (a latch that trips on a lagging pressure,
    e.g. the clutch's after a dwell), on a falling ramp nothing moves (such a latch
    releases on its own spring). ``r`` depends on no pressure and not on the latch's
    opening: a pilot blended with its own lag by ``1 − λ`` made the latch chatter, and
    :class:`LatchPilotLag` delays the release as much as the snap (held-back error +6 % on
    a circuit whose release does not lag; session 62). ``r = 0`` (the default) is exactly
    today's model; without a commanded current (``current_cmd_mA``) the law does nothing.

    The default fit adds it after its solver and its latch band stages where the slow and
    fast training ramps' snaps ask for it, held at the values they give
    (:mod:`~clutchlab.physics.fit.latch_lag`).
    """

    name = "latch_on_lag"
    description = "latch-on delayed in proportion to the rising command's rate (release not)"
    signature = (
        "latch snap lags the current more at fast ramps than the model's; the release does "
        "not; regulated branch and latched plateau unaffected"
    )
    PARAMETERS = (
        param(
            "lolag", "r", "bar", 0.0, 0.0, 5.0, "pilot offset per 1 A/s of rising ramp", "linear"
        ),
    )
    STRENGTH = ()
    FIT = ("lolag_r",)
    WARM_ONLY = True

    def apply(self, asm: Assembly) -> None:
        rate_mA_s = _command_rate(asm, "i_rate_on", self.name)

        def pilot(a, prev):
            rising = 0.5 * (rate_mA_s(a) + ca.sqrt(rate_mA_s(a) ** 2 + 1.0)) / 1000.0
            return prev - a.p("lolag_r") * rising

        asm.wrap("p_latch_pilot", pilot)


#: Reference dither frequency (Hz) of :class:`LatchDitherBand`'s frequency terms.
BAND_F_REF_HZ = 50.0
#: Dither amplitude (mA) per unit of :class:`LatchDitherBand`'s amplitude terms.
BAND_A_REF_MA = 100.0
#: Dither amplitude (mA) at which :class:`LatchDitherBand`'s frequency-only terms are
#: half on (they act only where there is a dither).
BAND_A_ON_MA = 10.0


def _octaves(freq_Hz, log):
    """``log₂(√(f² + 1) / 50 Hz)``: the dither frequency in octaves from the reference
    (smooth, ≥ 1 Hz without dither)."""
    return log((freq_Hz**2 + 1.0) ** 0.5 / BAND_F_REF_HZ) / math.log(2.0)


def dither_band_terms(amp_mA, freq_Hz, log=np.log) -> tuple:
    """The five terms of :class:`LatchDitherBand`'s half-width, one per parameter.

    ``w = Σ p_i t_i`` with ``(t_i) = (g v, g v², a/100, a/100 · v, a/100 · v²)``, ``a`` the
    dither amplitude (mA), ``v = log₂(√(f² + 1) / 50 Hz)`` (smooth, ≥ 1 Hz without dither)
    and ``g = a / (a + 10 mA)``; in the order of ``LatchDitherBand.FIT``.

    Parameters
    ----------
    amp_mA, freq_Hz : float, ndarray or CasADi expression
        Dither amplitude (mA) and frequency (Hz).
    log : callable
        Natural logarithm for the argument type (``numpy.log``, ``casadi.log``).

    Returns
    -------
    tuple
        The five terms (per unit of their parameter, bar).
    """
    v = _octaves(freq_Hz, log)
    gate = amp_mA / (amp_mA + BAND_A_ON_MA)
    scale = amp_mA / BAND_A_REF_MA
    return (gate * v, gate * v * v, scale, scale * v, scale * v * v)


#: Ramp rate (mA/s) per unit of :class:`LatchRateBand`'s terms.
RATE_REF_MA_S = 1000.0
#: Time constant (s) of the filter of the commanded current whose output gives
#: :class:`LatchRateBand` the ramp rate (settled within ~0.15 s of a ramp's start).
RATE_FILTER_S = 0.05
#: Rate (mA/s) below which the smooth ``|R|`` of :class:`LatchRateBand` rounds off.
_RATE_ROUND_MA_S = 1.0


def rate_band_terms(amp_mA, freq_Hz, rate_mA_s, log=np.log, sqrt=np.sqrt) -> tuple:
    """The three terms of :class:`LatchRateBand`'s half-width, one per parameter.

    ``w = r₀ s + q₀ s a/100 + q₁ s a/100 · v`` with ``s = |R| / 1000 mA/s``, ``R`` the
    commanded current's ramp rate (mA/s; ``|R|`` smooth), ``a`` the dither amplitude (mA)
    and ``v`` the dither frequency in octaves from 50 Hz (as :func:`dither_band_terms`); in
    the order of ``LatchRateBand.FIT``.

    Parameters
    ----------
    amp_mA, freq_Hz, rate_mA_s : float, ndarray or CasADi expression
        Dither amplitude (mA), dither frequency (Hz) and ramp rate (mA/s).
    log, sqrt : callable
        Natural logarithm and square root for the argument type (NumPy or CasADi).

    Returns
    -------
    tuple
        The three terms (per unit of their parameter, bar).
    """
    s = sqrt(rate_mA_s**2 + _RATE_ROUND_MA_S**2) / RATE_REF_MA_S
    sa = s * amp_mA / BAND_A_REF_MA
    return (s, sa, sa * _octaves(freq_Hz, log))


class LatchDitherBand(Effect):
    """A latch hysteresis band that depends on the dither amplitude and frequency.

    The latch valve sees ``p_l = p_a + (2λ − 1) w`` with ``λ`` its opening and the
    half-width change (bar)

    ``w = g(a) (c₁ v + c₂ v²) + (a / 100 mA) (k₀ + k₁ v + k₂ v²)``,
    ``v = log₂(f / 50 Hz)``, ``g(a) = a / (a + 10 mA)``,

    ``a`` the logged dither amplitude (mA) and ``f`` the dither frequency (Hz). ``w > 0``
    delays both the snap (unlatched, the pilot looks lower by ``w``) and the release
    (latched, higher by ``w``): the band widens by ``2w`` in pilot pressure. The model's
    latch switches on the dithered pilot, i.e. near the dither's crest; a latch that
    must see its pilot beyond a threshold for a dwell time (trough-tripping when the dwell
    exceeds the dither period), or whose pilot passage filters the dither, switches at
    currents that move with the dither amplitude by an amount that depends on the
    frequency (the zoo's quadratic_play, saturating_lugre). The centre of the band stays
    with the latch's own thresholds. All five parameters at 0 (the default) is exactly
    today's model; without dither (``a = 0``) the law does nothing.

    The default fit adds it after its solver where the slow ramps' latch snaps ask for it,
    held at the values the snaps give (``FitSettings.latch_band``,
    :mod:`~clutchlab.physics.fit.latch_band`); it can also be fitted from a fit already
    made, ``clutchlab fit-physics DATA --start FIT.json --effects latch_dither_band``
    (:attr:`WARM_ONLY`).
    """

    name = "latch_dither_band"
    description = "latch hysteresis band that changes with dither amplitude and frequency"
    signature = (
        "latch snap and release currents that move apart (or together) with the dither "
        "amplitude, by amounts that differ between dither frequencies; the same at every "
        "ramp rate"
    )
    PARAMETERS = (
        param("ldb", "c1", "bar", 0.0, -5.0, 5.0, "half-width per octave of dither", "linear"),
        param("ldb", "c2", "bar", 0.0, -5.0, 5.0, "half-width per octave², dither", "linear"),
        param("ldb", "k0", "bar", 0.0, -5.0, 5.0, "half-width per 100 mA of dither", "linear"),
        param("ldb", "k1", "bar", 0.0, -5.0, 5.0, "same, per octave of dither", "linear"),
        param("ldb", "k2", "bar", 0.0, -5.0, 5.0, "same, per octave² of dither", "linear"),
    )
    # signed (a band can widen or narrow): fitted parameters, not one-sided strengths
    STRENGTH = ()
    #: Added to a fit already made (the fit's latch band stage, or ``fit-physics --start
    #: FIT.json --effects latch_dither_band``): fitted from the datasheet start it did worse
    #: (session 55, E4), so no structure selection fits it from there.
    WARM_ONLY = True
    FIT = ("ldb_c1", "ldb_c2", "ldb_k0", "ldb_k1", "ldb_k2")

    def apply(self, asm: Assembly) -> None:
        def pilot(a, prev):
            terms = dither_band_terms(a.u["dither_amp_mA"], a.u["dither_freq_Hz"], ca.log)
            w = sum(a.p(n) * t for n, t in zip(self.FIT, terms, strict=True))
            return prev + (2.0 * a.x("latch") - 1.0) * w

        asm.wrap("p_latch_pilot", pilot)


class LatchRateBand(Effect):
    """A latch hysteresis band that changes with the ramp rate, by an amount that depends on
    the dither.

    The latch valve sees ``p_l = p_a + (2λ − 1) w`` with ``λ`` its opening and the
    half-width change (bar)

    ``w = (|R| / 1000 mA/s)(r₀ + (a / 100 mA)(q₀ + q₁ v))``, ``v = log₂(f / 50 Hz)``,

    ``R`` the ramp rate of the commanded current (mA/s), taken from a 50 ms filter of the
    command (a state), ``a`` the logged dither amplitude (mA) and ``f`` its frequency (Hz).
    :class:`LatchDitherBand` moves the switch currents with the dither by the same amount at
    every ramp rate. A latch that needs its pilot beyond a threshold for a dwell time does
    not: the dwell delays both switches by the distance the current ramps in it (``r₀``),
    and on a fast ramp the pilot's mean climbs through the dither's reach within the dwell,
    so the dither moves the switch currents less than on a slow ramp (``q₀``, ``q₁``; the
    zoo's quadratic_play: the slow ramps' snaps matched, the fast ramps' late by ~0.1-0.15
    mA per mA of dither at 440 mA/s, half that at 220 mA/s). ``w > 0`` widens the band.
    All three parameters at 0 (the default) is exactly today's model; without a commanded
    current (``current_cmd_mA``) the law does nothing, without dither only ``r₀`` acts.

    The default fit adds it after its solver and the latch band stage where the faster
    training ramps' snaps ask for it, held at the values they give
    (:mod:`~clutchlab.physics.fit.latch_rate`).
    """

    name = "latch_rate_band"
    description = "latch band that changes with the ramp rate, by an amount set by the dither"
    signature = (
        "latch snap and release currents on the fast ramps off by amounts that grow with "
        "the ramp rate and the dither amplitude while the slow ramps' are matched"
    )
    PARAMETERS = (
        param("lrb", "r0", "bar", 0.0, -5.0, 5.0, "half-width per 1 A/s of ramp", "linear"),
        param("lrb", "q0", "bar", 0.0, -5.0, 5.0, "same, per 100 mA of dither", "linear"),
        param("lrb", "q1", "bar", 0.0, -5.0, 5.0, "same, per octave of dither", "linear"),
    )
    # signed: fitted parameters, not one-sided strengths
    STRENGTH = ()
    #: Added to a fit already made only (as :class:`LatchDitherBand`).
    WARM_ONLY = True
    FIT = ("lrb_r0", "lrb_q0", "lrb_q1")

    def apply(self, asm: Assembly) -> None:
        rate_mA_s = _command_rate(asm, "i_rate", self.name)

        def pilot(a, prev):
            terms = rate_band_terms(
                a.u["dither_amp_mA"], a.u["dither_freq_Hz"], rate_mA_s(a), ca.log, ca.sqrt
            )
            w = sum(a.p(n) * t for n, t in zip(self.FIT, terms, strict=True))
            return prev + (2.0 * a.x("latch") - 1.0) * w

        asm.wrap("p_latch_pilot", pilot)


class LatchLineThreshold(Effect):
    """Latch-on and latch-off thresholds that move with line pressure.

    The latch valve sees ``p_l = p_a − ((1 − λ) r_on + λ r_off)(p_line − p_ref)`` with
    ``λ`` its opening: closed, its latch-on threshold lies ``r_on`` bar higher per bar of
    line pressure above ``p_ref``; open, its latch-off threshold ``r_off`` bar higher. A
    latch valve whose reference face is fed by line pressure (a differential valve
    balanced against line, not against its spring alone) snaps and releases at pilot
    pressures proportional to line, so its switch currents follow the line pressure's
    wander from run to run and within a run; the datasheet valve's do not. The smooth
    valve is part-open near its release, so ``r_on`` moves the release too (about half as
    far as the snap, on the stand's fast ramp). ``r_on = r_off = 0`` (the default) is
    exactly today's model; without a logged line pressure the line is the nominal one and
    the law does nothing.

    A fit (``FitSettings.latch_band = "auto"``, the default) adds it after its solver,
    with :class:`LatchDitherBand` or alone, where the quasi-static snaps ask for it
    (:mod:`~clutchlab.physics.fit.latch_band`): ``p_ref`` is then held at the median line
    pressure at the snaps and ``r_on``, ``r_off`` at the values the snaps give
    (:attr:`WARM_ONLY`).
    """

    name = "latch_line_threshold"
    description = "latch-on / latch-off thresholds that move with line pressure"
    signature = (
        "latch snap and release currents that follow the line pressure at the switch "
        "(higher line, later snap), at every ramp rate and dither"
    )
    PARAMETERS = (
        param("llt", "r_on", "-", 0.0, -3.0, 3.0, "latch-on threshold per bar of line", "linear"),
        param("llt", "r_off", "-", 0.0, -3.0, 3.0, "latch-off threshold per bar of line", "linear"),
        param(
            "llt", "p_ref", "bar", LINE_PRESSURE_BAR, 1.0, 100.0, "line pressure of the thresholds"
        ),
    )
    # signed slopes: fitted parameters, not one-sided strengths; p_ref is held
    STRENGTH = ()
    WARM_ONLY = True
    FIT = ("llt_r_on", "llt_r_off")

    def apply(self, asm: Assembly) -> None:
        def pilot(a, prev):
            lam = a.x("latch")
            slope = (1.0 - lam) * a.p("llt_r_on") + lam * a.p("llt_r_off")
            return prev - slope * (a["p_line"] - a.p("llt_p_ref"))

        asm.wrap("p_latch_pilot", pilot)


def switched_on(model) -> dict[str, float]:
    """Start values that switch on ``model``'s held switches: ``{weight: 1.0}``.

    A held switch is a flexible law whose strength (a weight, default 0: today's model) a
    fit does not free — ``reg_pilot_lag`` (``rlag_w``), ``latch_pilot_lag`` (``llag_w``),
    ``latch_line_select`` (``lsel_w``). Named on a model to be fitted, such a law is meant
    on: at weight 0 it would act on nothing and its own fit parameters would be
    unidentifiable.

    Parameters
    ----------
    model : CircuitModel
        The model to be fitted.

    Returns
    -------
    dict of str to float
        The held weights of ``model``'s flexible laws, each at 1.0; empty when it has none.
    """
    out: dict[str, float] = {}
    for effect in model.effects:
        if effect.HELD_SWITCH:
            out.update(dict.fromkeys(effect.STRENGTH, 1.0))
    return out
