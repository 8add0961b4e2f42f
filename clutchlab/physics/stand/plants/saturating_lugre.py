"""Plant ``saturating_lugre``: saturating solenoid, LuGre spool friction, pressure-threshold latch.

Written for the zoo, independently of clutchlab's fit model (own equations, own code).
Where it differs from the fit model:

- **magnetic characteristic**: pilot-equivalent pressure ``P_sat·tanh(i_e/i_sat)`` of the
  current above a threshold: it saturates at high current (the fit model's is a
  square-law knee into a straight line);
- **friction**: LuGre bristle model on the pilot/regulator spool (pre-sliding, Stribeck
  curve, viscous term);
- **spool**: a second-order mass–spring–damper in pilot-equivalent pressure;
- **regulator / fill**: the clutch follows the spool with an accumulator lag whose
  compliance grows at low pressure (entrained air);
- **latch**: switches on thresholds of a filtered pilot pressure only, with a finite
  stroke time; latched, the clutch sees line pressure;
- **sensor**: first-order lag.

State: coil current (mA), spool position and velocity (bar, bar/s), bristle deflection
(bar), clutch pressure (bar), latch pilot (bar), latch stroke (0–1), sensor (bar).
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
    P("i0_mA", 130.0, 170.0, "mA", "current where the pilot pressure starts to rise"),
    P("isat_mA", 1500.0, 2100.0, "mA", "saturation current scale of the magnetic circuit"),
    P("gain_bar_A", 19.0, 22.0, "bar/A", "initial slope of pilot-equivalent pressure"),
    P("f_spool_Hz", 25.0, 40.0, "Hz", "natural frequency of the spool"),
    P("zeta", 0.5, 0.8, "1", "damping ratio of the spool"),
    P("fc_bar", 0.10, 0.22, "bar", "Coulomb friction (pilot-equivalent)"),
    P("fs_ratio", 1.3, 1.8, "1", "breakaway / Coulomb friction"),
    P("vs_bar_s", 2.0, 6.0, "bar/s", "Stribeck velocity"),
    P("visc_bar_s", 2e-4, 6e-4, "s", "viscous friction (bar per bar/s)"),
    P("tau_fill_ms", 80.0, 120.0, "ms", "clutch-fill (accumulator) time constant"),
    P("air", 0.3, 0.8, "1", "extra fill lag at low pressure (entrained air)"),
    P("p_on_bar", 14.4, 15.0, "bar", "latch-on threshold of the latch pilot"),
    P("p_off_bar", 12.4, 12.9, "bar", "latch-off threshold of the latch pilot"),
    P("tau_lpilot_ms", 15.0, 30.0, "ms", "latch pilot filter"),
    P("stroke_ms", 8.0, 20.0, "ms", "latch stroke time"),
    P("tau_s_ms", 2.0, 5.0, "ms", "pressure sensor lag"),
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
    tau_i = par[0] * 1e-3
    i0, isat, gain = par[1], par[2], par[3]
    wn = 2.0 * math.pi * par[4]
    zeta, fc = par[5], par[6]
    fs = fc * par[7]
    vs, visc = par[8], par[9]
    tau_fill, air = par[10] * 1e-3, par[11]
    p_on, p_off = par[12], par[13]
    tau_lp, stroke, tau_s = par[14] * 1e-3, par[15] * 1e-3, par[16] * 1e-3
    temp_visc, temp_leak, c_line, droop, leak = par[17], par[18], par[19], par[20], par[21]
    tau_lag = par[22] * 1e-3
    psat = gain * isat / 1000.0
    sig0 = fs / 0.01  # bristle stiffness: breakaway at 0.01 bar of pre-sliding
    sig1 = 2.0 * 0.7 * math.sqrt(sig0) / wn
    n = len(inom)
    i_out = np.empty(n)
    p_out = np.empty(n)
    ic = 0.0
    x = prime[0]
    v = 0.0
    z = 0.0
    pc = prime[0]
    lp = prime[0]
    s = 0.0
    latched = False
    ps = prime[0]
    pl = prime[0]
    for k in range(n):
        nu = math.exp(-(temp[k] - 55.0) / 30.0)  # relative viscosity
        for j in range(sub):
            ph = ph0 + freq * (k * sub + j) * dt
            icmd = max(inom[k] + amp[k] * dither_wave(ph, tri), 0.0)
            ic += dt * (icmd - ic) / tau_i
            pm = psat * math.tanh(softplus(ic - i0, 10.0) / isat)
            g = fc + (fs - fc) * math.exp(-((v / vs) ** 2))
            a = sig0 * abs(v) / g
            if a > 0.0:
                zss = math.copysign(g / sig0, v)
                z_new = zss + (z - zss) * math.exp(-a * dt)
            else:
                z_new = z
            zdot = (z_new - z) / dt
            z = z_new
            f = sig0 * z + sig1 * zdot + visc * v
            v += dt * (wn * wn * (pm - x - f) - 2.0 * zeta * wn * v)
            x += dt * v
            ptar = x * (1.0 - leak * x - temp_leak * (temp[k] - 55.0) / 30.0)
            ptar += c_line * (line[k] - 17.7)
            ptar = prime[k] + softplus(ptar - prime[k], 0.1)
            tf = tau_fill * (1.0 + air * math.exp(-pc / 1.5)) * nu**temp_visc
            dpc = (ptar - pc) / tf
            pc += dt * dpc
            lp += dt * (x - lp) / tau_lp
            if not latched and lp > p_on:
                latched = True
            elif latched and lp < p_off:
                latched = False
            s = min(max(s + (dt / stroke if latched else -dt / stroke), 0.0), 1.0)
            supply = line[k] - droop * max(dpc, 0.0)
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
    name="saturating_lugre",
    summary="saturating solenoid, LuGre friction on a 2nd-order spool, threshold latch",
    laws={
        "magnetic": "saturating tanh characteristic",
        "friction": "LuGre (bristle) with Stribeck curve",
        "spool": "second-order mass-spring-damper",
        "latch": "pilot-pressure thresholds only, finite stroke",
        "fill": "accumulator lag growing at low pressure",
        "sensor": "first-order lag",
    },
    parameters=PARAMETERS,
    effects=standard_effects(
        oil_temperature="fill lag follows oil viscosity; leakage deficit when hot",
        supply_droop="regulated pressure follows line; latched supply droops with fill rate",
        spool_leakage="pressure deficit growing with pressure",
    ),
    refused=standard_refusals(
        stribeck_friction="its LuGre friction already has a Stribeck curve",
        vfs_magnetic_hysteresis="its magnetic circuit is single-valued; hysteresis is in the "
        "LuGre friction",
    ),
    simulate=_kernel,
)
