"""Plant ``quadratic_play``: square-law solenoid, play-operator hysteresis, dwell-timer latch.

Written for the zoo, independently of clutchlab's fit model (own equations, own code).
Where it differs from the fit model:

- **magnetic characteristic**: square law in the current above a threshold up to a
  knee, straight beyond (C¹ at the knee);
- **hysteresis**: a Prandtl–Ishlinskii operator (weighted backlash / play operators of
  25, 60 and 120 mA) on the armature current; dither larger than a play width wipes
  that play's hysteresis out, so the loop width depends on the dither setting;
- **spool**: quasi-static, a first-order lag (no mass);
- **regulator**: finite loop gain and a droop near line pressure; the clutch fills
  faster than it drains (asymmetric fill and drain lags);
- **latch**: a dwell timer: it switches only after the pilot has stayed beyond a
  threshold for a dwell time, and the clutch then fills to line through a lag;
- **sensor**: two-pole (critically damped) filter.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .base import PlantParameter, PlantSpec
from .common import dither_wave, softplus
from .effects import standard_effects, standard_refusals

#: Widths (mA) of the play operators.
PLAY_WIDTHS_MA = (25.0, 60.0, 120.0)

P = PlantParameter
PARAMETERS = (
    P("tau_i_ms", 1.0, 2.5, "ms", "current-loop time constant"),
    P("tau_arm_ms", 4.0, 8.0, "ms", "armature lag"),
    P("i0_mA", 90.0, 130.0, "mA", "current where the pilot pressure starts to rise"),
    P("ik_mA", 120.0, 180.0, "mA", "knee of the square law above i0"),
    P("gain_bar_A", 19.0, 23.0, "bar/A", "slope of the pilot-equivalent pressure"),
    P("h1", 0.03, 0.08, "1", "weight of the 25 mA play"),
    P("h2", 0.03, 0.08, "1", "weight of the 60 mA play"),
    P("h3", 0.02, 0.06, "1", "weight of the 120 mA play"),
    P("tau_sp_ms", 3.0, 6.0, "ms", "spool lag"),
    P("loop_gain", 12.0, 30.0, "1", "regulator loop gain"),
    P("droop", 0.02, 0.05, "1", "regulator droop near line pressure"),
    P("tau_fill_ms", 80.0, 110.0, "ms", "fill lag"),
    P("drain_ratio", 1.1, 1.5, "1", "drain lag / fill lag"),
    P("p_on_bar", 15.2, 15.8, "bar", "latch-on threshold of the pilot"),
    P("p_off_bar", 13.2, 13.8, "bar", "latch-off threshold of the pilot"),
    P("dwell_ms", 15.0, 40.0, "ms", "latch dwell time"),
    P("tau_latch_ms", 8.0, 15.0, "ms", "latch fill lag"),
    P("f_sensor_Hz", 40.0, 80.0, "Hz", "sensor filter corner"),
    # Library effects, zero unless switched on (see .effects).
    P("temp_visc", 0.0, 0.0, "1", "viscosity exponent of the fill lag (oil_temperature)"),
    P("temp_leak", 0.0, 0.0, "1", "pressure deficit per 30 °C above 55 °C (oil_temperature)"),
    P("line_coupling", 0.0, 0.0, "1", "regulated pressure per bar of line (supply_droop)"),
    P("droop_s", 0.0, 0.0, "s", "supply droop per fill rate (supply_droop)"),
    P("leak", 0.0, 0.0, "1", "leakage deficit per bar (spool_leakage)"),
    P("tau_lag_ms", 0.0, 0.0, "ms", "extra sensor lag (sensor_lag)"),
    P("delay_ms", 0.0, 0.0, "ms", "transport delay (transport_delay)"),
)


@njit(cache=True)
def _play(y, u, r):
    """Backlash (play) operator of half-width ``r``: output ``y`` follows ``u`` within ±r."""
    if u - y > r:
        return u - r
    if y - u > r:
        return u + r
    return y


@njit(cache=True)
def _kernel(par, dt, sub, inom, amp, freq, ph0, tri, line, prime, temp):
    tau_i, tau_arm = par[0] * 1e-3, par[1] * 1e-3
    i0, ik, gain = par[2], par[3], par[4] / 1000.0
    h1, h2, h3 = par[5], par[6], par[7]
    h0 = 1.0 - h1 - h2 - h3
    tau_sp = par[8] * 1e-3
    g_loop, droop = par[9], par[10]
    tau_fill = par[11] * 1e-3
    drain = par[12]
    p_on, p_off = par[13], par[14]
    dwell, tau_latch = par[15] * 1e-3, par[16] * 1e-3
    ws = 2.0 * math.pi * par[17]
    temp_visc, temp_leak, c_line, droop_s, leak = par[18], par[19], par[20], par[21], par[22]
    tau_lag = par[23] * 1e-3
    r1, r2, r3 = 0.5 * 25.0, 0.5 * 60.0, 0.5 * 120.0
    n = len(inom)
    i_out = np.empty(n)
    p_out = np.empty(n)
    ic = 0.0
    ia = 0.0
    y1 = y2 = y3 = 0.0
    x = prime[0]
    pc = prime[0]
    pcl = prime[0]
    latched = False
    timer = 0.0
    s1 = prime[0]
    s2 = 0.0
    pl = prime[0]
    for k in range(n):
        nu = math.exp(-(temp[k] - 55.0) / 30.0)
        for j in range(sub):
            ph = ph0 + freq * (k * sub + j) * dt
            icmd = max(inom[k] + amp[k] * dither_wave(ph, tri), 0.0)
            ic += dt * (icmd - ic) / tau_i
            ia += dt * (ic - ia) / tau_arm
            y1 = _play(y1, ia, r1)
            y2 = _play(y2, ia, r2)
            y3 = _play(y3, ia, r3)
            ih = h0 * ia + h1 * y1 + h2 * y2 + h3 * y3
            ie = softplus(ih - i0, 5.0)
            if ie < ik:
                pm = gain * ie * ie / (2.0 * ik)
            else:
                pm = gain * (ie - 0.5 * ik)
            x += dt * (pm - x) / tau_sp
            ptar = (g_loop * x + prime[k]) / (1.0 + g_loop) - droop * x * x / line[k]
            ptar *= 1.0 - leak * x - temp_leak * (temp[k] - 55.0) / 30.0
            ptar += c_line * (line[k] - 17.7)
            ptar = prime[k] + softplus(ptar - prime[k], 0.1)
            tf = tau_fill * nu**temp_visc
            if ptar < pc:
                tf *= drain
            dpc = (ptar - pc) / tf
            pc += dt * dpc
            if latched != (x > p_on if not latched else x >= p_off):
                timer += dt
                if timer >= dwell:
                    latched = not latched
                    timer = 0.0
            else:
                timer = 0.0
            supply = line[k] - droop_s * max(dpc, 0.0)
            target = supply if latched else pc
            pcl += dt * (target - pcl) / tau_latch
            p = pcl
            # two-pole critically damped sensor
            s2 += dt * (ws * ws * (p - s1) - 2.0 * ws * s2)
            s1 += dt * s2
            if tau_lag > 0.0:
                pl += dt * (s1 - pl) / tau_lag
            else:
                pl = s1
        i_out[k] = ic
        p_out[k] = pl
    return i_out, p_out


SPEC = PlantSpec(
    name="quadratic_play",
    summary="square-law solenoid, play-operator hysteresis, quasi-static spool, dwell latch",
    laws={
        "magnetic": "square law up to a knee, then straight",
        "hysteresis": "Prandtl-Ishlinskii play operators (25/60/120 mA)",
        "spool": "quasi-static first-order lag",
        "regulator": "finite loop gain, droop near line, asymmetric fill/drain",
        "latch": "dwell timer on pilot thresholds, fill lag to line",
        "sensor": "two-pole filter",
    },
    parameters=PARAMETERS,
    effects=standard_effects(
        oil_temperature="fill and drain lags follow oil viscosity; leakage deficit when hot",
        supply_droop="regulated pressure follows line; latched supply droops with fill rate",
        spool_leakage="pressure deficit growing with pilot pressure",
    ),
    refused=standard_refusals(
        stribeck_friction="its spool is quasi-static (no mass, no friction state)",
        dither_friction_reduction="its hysteresis already shrinks with dither (play operators)",
        vfs_magnetic_hysteresis="its play operators are its magnetic/mechanical hysteresis",
    ),
    simulate=_kernel,
)
