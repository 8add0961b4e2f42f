"""Plant ``stribeck_supply``: kinked solenoid with eddy lag, stick–slip spool, supply-limited fill.

Written for the zoo, independently of clutchlab's fit model (own equations, own code).
Where it differs from the fit model:

- **magnetic characteristic**: two straight segments joined by a rounded kink, and an
  eddy-current lag of the force behind the current;
- **friction**: Karnopp stick–slip with a Stribeck curve (the spool sticks while the
  applied force stays below breakaway);
- **spool**: second-order mass–spring–damper;
- **regulator / fill**: the regulated pressure follows line pressure, and the fill rate
  is limited by the supply (orifice flow ∝ √(line − p)) and the drain by the clutch
  pressure (∝ √(p − prime));
- **latch**: thresholds proportional to line pressure (a differential-area valve fed by
  line), finite stroke;
- **sensor**: first-order lag and a transport delay.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .base import PlantParameter, PlantSpec
from .common import dither_wave, softplus
from .effects import standard_effects, standard_refusals

P = PlantParameter
PARAMETERS = (
    P("tau_i_ms", 0.8, 2.0, "ms", "current-loop time constant"),
    P("tau_eddy_ms", 2.0, 6.0, "ms", "eddy-current lag of the magnetic force"),
    P("i0_mA", 140.0, 170.0, "mA", "current where the pilot pressure starts to rise"),
    P("gain_bar_A", 19.0, 22.0, "bar/A", "slope below the kink"),
    P("kink_mA", 450.0, 650.0, "mA", "kink of the characteristic"),
    P("slope_ratio", 0.9, 1.1, "1", "slope above / below the kink"),
    P("f_spool_Hz", 20.0, 35.0, "Hz", "natural frequency of the spool"),
    P("zeta", 0.6, 0.9, "1", "damping ratio of the spool"),
    P("fc_bar", 0.08, 0.18, "bar", "Coulomb friction (pilot-equivalent)"),
    P("fs_ratio", 1.4, 2.0, "1", "breakaway / Coulomb friction"),
    P("vs_bar_s", 1.0, 4.0, "bar/s", "Stribeck velocity"),
    P("line_gain", 0.05, 0.2, "1", "regulated pressure per bar of line deviation"),
    P("tau_fill_ms", 70.0, 100.0, "ms", "fill lag at 8 bar below line"),
    P("lat_on", 0.85, 0.88, "1", "latch-on threshold / line pressure"),
    P("lat_off", 0.72, 0.75, "1", "latch-off threshold / line pressure"),
    P("tau_lpilot_ms", 15.0, 30.0, "ms", "latch pilot filter"),
    P("stroke_ms", 6.0, 12.0, "ms", "latch stroke time"),
    P("tau_s_ms", 3.0, 8.0, "ms", "pressure sensor lag"),
    P("dead_ms", 2.0, 6.0, "ms", "transport delay of the pressure reading"),
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
def _kernel(par, dt, sub, inom, amp, freq, ph0, tri, line, prime, temp):
    tau_i, tau_e = par[0] * 1e-3, par[1] * 1e-3
    i0, g1, kink, ratio = par[2], par[3] / 1000.0, par[4], par[5]
    wn = 2.0 * math.pi * par[6]
    zeta, fc = par[7], par[8]
    fs = fc * par[9]
    vs = par[10]
    line_gain = par[11]
    tau_fill = par[12] * 1e-3
    lat_on, lat_off = par[13], par[14]
    tau_lp, stroke, tau_s = par[15] * 1e-3, par[16] * 1e-3, par[17] * 1e-3
    temp_visc, temp_leak, c_line, droop_s, leak = par[19], par[20], par[21], par[22], par[23]
    tau_lag = par[24] * 1e-3
    v_stick = 0.05  # bar/s: below this the spool may stick
    n = len(inom)
    i_out = np.empty(n)
    p_out = np.empty(n)
    ic = 0.0
    fe = 0.0
    x = prime[0]
    v = 0.0
    pc = prime[0]
    lp = prime[0]
    s = 0.0
    latched = False
    ps = prime[0]
    pl = prime[0]
    for k in range(n):
        nu = math.exp(-(temp[k] - 55.0) / 30.0)
        for j in range(sub):
            ph = ph0 + freq * (k * sub + j) * dt
            icmd = max(inom[k] + amp[k] * dither_wave(ph, tri), 0.0)
            ic += dt * (icmd - ic) / tau_i
            ie = softplus(ic - i0, 8.0)
            pm = g1 * ie + g1 * (ratio - 1.0) * softplus(ie - (kink - i0), 30.0)
            fe += dt * (pm - fe) / tau_e
            applied = wn * wn * (fe - x) - 2.0 * zeta * wn * v
            if abs(v) < v_stick and abs(fe - x) <= fs:
                v = 0.0  # stuck: friction takes the applied force
            else:
                sgn = math.copysign(1.0, v if abs(v) >= v_stick else fe - x)
                fr = (fc + (fs - fc) * math.exp(-((v / vs) ** 2))) * sgn
                v += dt * (applied - wn * wn * fr)
            x += dt * v
            ptar = x * (1.0 - leak * x - temp_leak * (temp[k] - 55.0) / 30.0)
            ptar += (line_gain + c_line) * (line[k] - 17.7)
            ptar = prime[k] + softplus(ptar - prime[k], 0.1)
            tf = tau_fill * nu**temp_visc
            if ptar > pc:
                rate = (ptar - pc) / tf * math.sqrt(max(line[k] - pc, 0.05) / 8.0)
            else:
                rate = (ptar - pc) / tf * math.sqrt(max(pc - prime[k], 0.05) / 8.0 + 0.5)
            pc += dt * rate
            lp += dt * (x - lp) / tau_lp
            if not latched and lp > lat_on * line[k]:
                latched = True
            elif latched and lp < lat_off * line[k]:
                latched = False
            s = min(max(s + (dt / stroke if latched else -dt / stroke), 0.0), 1.0)
            supply = line[k] - droop_s * max(rate, 0.0)
            p = pc + s * (supply - pc)
            ps += dt * (p - ps) / tau_s
            if tau_lag > 0.0:
                pl += dt * (ps - pl) / tau_lag
            else:
                pl = ps
        i_out[k] = ic
        p_out[k] = pl
    return i_out, p_out


SPEC = PlantSpec(
    name="stribeck_supply",
    summary="kinked solenoid with eddy lag, stick-slip spool, supply-limited fill, line latch",
    laws={
        "magnetic": "two slopes with a rounded kink, eddy-current force lag",
        "friction": "Karnopp stick-slip with Stribeck curve",
        "spool": "second-order mass-spring-damper",
        "regulator": "follows line pressure; fill limited by sqrt(line - p), drain by sqrt(p)",
        "latch": "thresholds proportional to line pressure, finite stroke",
        "sensor": "first-order lag and transport delay",
    },
    parameters=PARAMETERS,
    effects=standard_effects(
        oil_temperature="fill and drain follow oil viscosity; leakage deficit when hot",
        supply_droop="regulated pressure follows line more; latched supply droops with fill",
        spool_leakage="pressure deficit growing with pressure",
    ),
    refused=standard_refusals(
        stribeck_friction="its spool friction is already a Stribeck stick-slip law",
        eddy_current_lag="its magnetic force already lags the current (eddy currents)",
    ),
    simulate=_kernel,
)
