"""Plant ``preisach_accumulator``: Preisach hysteresis, orifice-fed progressive accumulator.

Written for the zoo, independently of clutchlab's fit model (own equations, own code).
Where it differs from the fit model:

- **hysteresis**: a Preisach operator of the magnetic circuit: 32 relays of random
  width (10–80 mA) and centre spread over the current range, drawn per seed; the
  magnetization offsets the effective current. Dither wider than a relay flips it every
  period, so the loop shrinks with dither amplitude;
- **spool**: quasi-static, a first-order lag;
- **fill**: clutch fed through a turbulent orifice (flow ∝ √Δp with a laminar core)
  into a progressive (stiffening) accumulator: the fill lag depends on the pressure
  difference and the pressure level, not a constant time;
- **latch**: switched by *clutch* pressure (not the pilot), with a dwell and a finite
  stroke;
- **sensor**: two-pole filter and a transport delay.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .base import PlantParameter, PlantSpec
from .common import dither_wave, softplus
from .effects import standard_effects, standard_refusals

#: Number of relays of the Preisach operator.
N_RELAYS = 32

P = PlantParameter
PARAMETERS = (
    P("tau_i_ms", 0.8, 2.5, "ms", "current-loop time constant"),
    P("i0_mA", 130.0, 170.0, "mA", "current where the pilot pressure starts to rise"),
    P("gain_bar_A", 19.0, 22.0, "bar/A", "slope of the pilot-equivalent pressure"),
    P("h_mA", 8.0, 20.0, "mA", "current offset of full magnetization"),
    P("relay_seed", 0.0, 1e6, "1", "seed of the relay widths and centres"),
    P("tau_sp_ms", 3.0, 7.0, "ms", "spool lag"),
    P("k_orf", 7.0, 10.0, "bar^0.5/s", "orifice flow coefficient over compliance"),
    P("p_lam_bar", 0.2, 0.4, "bar", "laminar core of the orifice law"),
    P("p_stiff_bar", 12.0, 20.0, "bar", "pressure where the accumulator stiffens ×2"),
    P("p_on_bar", 14.8, 15.6, "bar", "latch-on clutch pressure"),
    P("p_off_bar", 12.8, 13.4, "bar", "latch-off clutch pressure"),
    P("dwell_ms", 5.0, 20.0, "ms", "latch dwell"),
    P("stroke_ms", 5.0, 12.0, "ms", "latch stroke time"),
    P("f_sensor_Hz", 50.0, 100.0, "Hz", "sensor filter corner"),
    P("dead_ms", 1.0, 4.0, "ms", "transport delay of the pressure reading"),
    # Library effects, zero unless switched on (see .effects).
    P("temp_visc", 0.0, 0.0, "1", "viscosity exponent of the orifice flow (oil_temperature)"),
    P("temp_leak", 0.0, 0.0, "1", "pressure deficit per 30 °C above 55 °C (oil_temperature)"),
    P("line_coupling", 0.0, 0.0, "1", "regulated pressure per bar of line (supply_droop)"),
    P("droop_s", 0.0, 0.0, "s", "supply droop per fill rate (supply_droop)"),
    P("leak", 0.0, 0.0, "1", "leakage deficit per bar (spool_leakage)"),
    P("tau_lag_ms", 0.0, 0.0, "ms", "extra sensor lag (sensor_lag)"),
    P("delay_ms", 0.0, 0.0, "ms", "transport delay (transport_delay)"),
)


def relays(seed: float) -> tuple[np.ndarray, np.ndarray]:
    """Relay centres (mA) and half-widths (mA) of the Preisach operator of a unit."""
    rng = np.random.default_rng(int(seed))
    centres = np.sort(rng.uniform(100.0, 1000.0, N_RELAYS))
    half = rng.uniform(5.0, 40.0, N_RELAYS)
    return centres, half


@njit(cache=True)
def _kernel_core(par, lo, hi, dt, sub, inom, amp, freq, ph0, tri, line, prime, temp):
    tau_i = par[0] * 1e-3
    i0, gain, h = par[1], par[2] / 1000.0, par[3]
    tau_sp = par[5] * 1e-3
    k_orf, p_lam, p_stiff = par[6], par[7], par[8]
    p_on, p_off = par[9], par[10]
    dwell, stroke = par[11] * 1e-3, par[12] * 1e-3
    ws = 2.0 * math.pi * par[13]
    temp_visc, temp_leak, c_line, droop_s, leak = par[15], par[16], par[17], par[18], par[19]
    tau_lag = par[20] * 1e-3
    m = len(lo)
    state = -np.ones(m)
    n = len(inom)
    i_out = np.empty(n)
    p_out = np.empty(n)
    ic = 0.0
    x = prime[0]
    pc = prime[0]
    latched = False
    timer = 0.0
    s = 0.0
    s1 = prime[0]
    s2 = 0.0
    pl = prime[0]
    for k in range(n):
        nu = math.exp(-(temp[k] - 55.0) / 30.0)
        kq = k_orf / nu**temp_visc
        for j in range(sub):
            ph = ph0 + freq * (k * sub + j) * dt
            icmd = max(inom[k] + amp[k] * dither_wave(ph, tri), 0.0)
            ic += dt * (icmd - ic) / tau_i
            mag = 0.0
            for r in range(m):
                if ic > hi[r]:
                    state[r] = 1.0
                elif ic < lo[r]:
                    state[r] = -1.0
                mag += state[r]
            ie = softplus(ic - h * mag / m - i0, 8.0)
            pm = gain * ie
            x += dt * (pm - x) / tau_sp
            ptar = x * (1.0 - leak * x - temp_leak * (temp[k] - 55.0) / 30.0)
            ptar += c_line * (line[k] - 17.7)
            ptar = prime[k] + softplus(ptar - prime[k], 0.1)
            dp = ptar - pc
            stiff = 1.0 + (pc / p_stiff) ** 2
            rate = kq * stiff * dp / (dp * dp + p_lam * p_lam) ** 0.25
            pc += dt * rate
            if latched != (pc > p_on if not latched else pc >= p_off):
                timer += dt
                if timer >= dwell:
                    latched = not latched
                    timer = 0.0
            else:
                timer = 0.0
            s = min(max(s + (dt / stroke if latched else -dt / stroke), 0.0), 1.0)
            supply = line[k] - droop_s * max(rate, 0.0)
            p = pc + s * (supply - pc)
            s2 += dt * (ws * ws * (p - s1) - 2.0 * ws * s2)
            s1 += dt * s2
            if tau_lag > 0.0:
                pl += dt * (s1 - pl) / tau_lag
            else:
                pl = s1
        i_out[k] = ic
        p_out[k] = pl
    return i_out, p_out


def _kernel(par, dt, sub, inom, amp, freq, ph0, tri, line, prime, temp):
    centres, half = relays(par[4])
    return _kernel_core(
        par, centres - half, centres + half, dt, sub, inom, amp, freq, ph0, tri, line, prime, temp
    )


SPEC = PlantSpec(
    name="preisach_accumulator",
    summary="Preisach magnetic hysteresis, orifice-fed progressive accumulator, pressure latch",
    laws={
        "hysteresis": "Preisach operator (32 random relays) of the magnetic circuit",
        "spool": "quasi-static first-order lag",
        "fill": "turbulent orifice (sqrt law, laminar core) into a stiffening accumulator",
        "latch": "clutch-pressure thresholds with dwell and finite stroke",
        "sensor": "two-pole filter and transport delay",
    },
    parameters=PARAMETERS,
    effects=standard_effects(
        oil_temperature="orifice flow follows oil viscosity; leakage deficit when hot",
        supply_droop="regulated pressure follows line; latched supply droops with fill rate",
        spool_leakage="pressure deficit growing with pressure",
    ),
    refused=standard_refusals(
        vfs_magnetic_hysteresis="its Preisach operator is its magnetic hysteresis",
        stribeck_friction="its spool is quasi-static (no mass, no friction state)",
        accumulator_spring_nonlinearity="its accumulator is already progressive",
    ),
    simulate=_kernel,
)
