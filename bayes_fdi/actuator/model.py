"""Equations of the DAMADICS (DABLib v1.22) actuator, compiled with numba.

The model follows DABLib v1.22 (Bartyś & Syfert, Warsaw University of Technology, 2002; the
equations as read from its model file, summarised with their citations on the DAMADICS page of
the documentation, ``docs/damadics.md``, and in ``docs/actuator.md``): a positioner (set-point
filter, P controller sampled every 35 ms, E/P transducer with dead zone, lever feedback), a
pneumatic chamber (isothermal air mass and pressure, supply, vent, leaks), a spring-diaphragm
servomotor (mass, viscous damping, backlash friction, end stops), an equal-percentage valve on
water (choked flow, vapour pressure, density) and a bypass valve.

Two integrators share every algebraic equation (:func:`_simulate_run`):

``scheme=0`` (reference)
    DABLib's own fixed-step RK4 at 2.5 ms on the continuous states (set-point filter, air mass,
    chamber pressure, stem position and velocity); the non-smooth parts (backlash play
    operators, end-stop flags, clipping) and the Simulink Memory blocks (spring force and lower
    end-stop flag from the previous step's stem position, chamber flow from the step's start
    pressure) are updated once per step, as Simulink does at major steps.
``scheme=1`` (fast)
    Quasi-static double steps of 5 ms (7 per 35 ms controller period, so the controller and
    the 1 s output instants coincide with the reference's): the set-point filter is integrated
    exactly, the air mass explicitly, the chamber pressure from the isothermal law, and the
    stem's inertia (time constant m/c = 1.3 ms) is dropped, its position advanced by a linearly
    implicit Euler step that is stable for the stiff spring/damper/air-spring coupling, with
    backlash engagement resolved inside the step. For the first 50 ms after every 1 Hz input
    sample and after an abrupt fault change, where the input steps excite the stem's inertia
    and the chamber's velocity clip, it takes the reference's RK4 ticks instead. Measured
    agreement with the reference: about 1e-4 of full scale RMS on X' and F' (the noise is
    1.4e-3), except under large backlash (f4, f15), where the loop hunts and neither integrator
    is converged pointwise (see ``docs/actuator.md``).

All arrays are in physical units inside this module (m, Pa, °C, t/h). The parameters that may
differ from one valve to the next reach the kernels as the float64 vector of
`bayes_fdi.actuator.parameters.ActuatorParameters` (one row per run); the constants below are
the fixed geometry and the nominal values they default to.
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import njit, prange

from bayes_fdi.actuator.parameters import (
    F_RANGE,
    IDX_AREA,
    IDX_BACKLASH,
    IDX_DAMPING,
    IDX_F_GAIN,
    IDX_F_OFFSET,
    IDX_K_IN,
    IDX_KP,
    IDX_M_INIT,
    IDX_MASS,
    IDX_P1_GAIN,
    IDX_P1_OFFSET,
    IDX_P2_GAIN,
    IDX_P2_OFFSET,
    IDX_PLUG_AREA,
    IDX_PRELOAD,
    IDX_SPRING,
    IDX_SUPPLY,
    IDX_T1_GAIN,
    IDX_T1_OFFSET,
    IDX_TAU,
    IDX_VOLUME,
    IDX_X_GAIN,
    IDX_X_OFFSET,
    NOMINAL,
    P_RANGE,
    T_RANGE,
)
from bayes_fdi.actuator.valve import (
    KM_V,
    KM_X,
    clip_value,
    hydraulics,
    interp_table,
    total_flow,
    valve_position,
)

# Numba's own thread pool rather than OpenMP: OpenMP-launched kernels set the process-wide
# OpenMP thread count, which torch reads as its own intra-op thread count, so simulating would
# silently change the thread count (and summation order) of every torch model fitted later.
# Users who chose a layer themselves (NUMBA_THREADING_LAYER) keep it.
if numba.config.THREADING_LAYER == "default":
    numba.config.THREADING_LAYER = "workqueue"

__all__ = ["PARAMETERS", "simulate_batch"]

# --- fixed geometry and constants (DABLib v1.22) -------------------------------------------
X0 = 0.0381  # stroke [m]
PATM = 101325.0  # atmospheric pressure [Pa]
GRAV = 9.81  # [m/s^2]
PZ_MIN = 120e3  # below this the supply is treated as lost [Pa]
K_LEAK = 2e-7  # leak coefficient per unit fault [kg/(s sqrt(Pa))]
P_MAX = 700e3  # chamber pressure clip (absolute) [Pa]
M_MAX = 0.1  # chamber air mass clip [kg]
V_CLIP = 0.02  # stem speed clip in the chamber volume law [m/s]
T_CTRL = 0.035  # positioner sampling period [s]
LEVER_MIN, LEVER_MAX = -0.01, 0.05  # feedback lever clip [m]

EP_X = np.array([-1.0, -0.94, -0.54, 0.46, 0.86, 1.0])
EP_Y = np.array([-0.55, -0.55, -0.02, 0.02, 1.0, 1.0])

#: Nominal parameters (name -> (value, unit, meaning)) for documentation and tests; the
#: parameters a valve may change are the fields of `ActuatorParameters` (defaults: these values).
PARAMETERS: dict[str, tuple[float, str, str]] = {
    "X0": (X0, "m", "stem stroke"),
    "V0": (NOMINAL.chamber_volume, "m^3", "chamber dead volume"),
    "Ae": (NOMINAL.diaphragm_area, "m^2", "effective diaphragm area"),
    "m": (NOMINAL.mass, "kg", "moving mass"),
    "k": (NOMINAL.spring, "N/m", "spring + diaphragm stiffness"),
    "x0": (NOMINAL.preload, "m", "spring preload (25 % stroke)"),
    "c": (NOMINAL.damping, "N s/m", "viscous damping"),
    "Pz": (NOMINAL.supply_pressure, "Pa", "positioner supply pressure (gauge)"),
    "k_in": (NOMINAL.inflow_coefficient, "kg/(s Pa^0.5)", "chamber inflow coefficient"),
    "k_leak": (K_LEAK, "kg/(s Pa^0.5)", "chamber leak coefficient per unit f9, f10"),
    "tau_sp": (NOMINAL.setpoint_lag, "s", "each of the two set-point filter lags"),
    "Kp": (NOMINAL.positioner_gain, "-", "positioner proportional gain"),
    "T_ctrl": (T_CTRL, "s", "positioner sampling period"),
    "Kv": (NOMINAL.kv, "m^3/h", "valve flow coefficient (fully open)"),
    "Kv_bypass": (NOMINAL.kv_bypass, "m^3/h", "bypass flow coefficient (fully open)"),
    "d_plug": (NOMINAL.plug_diameter, "m", "plug diameter (plug force)"),
    "db": (NOMINAL.backlash * X0, "m", "nominal backlash (friction) width, 1 % of stroke"),
}

#: integration ticks per second (2.5 ms; the controller period, 35 ms, is 14 ticks). The
#: reference takes one RK4 step per tick, the fast scheme quasi-static steps of two ticks
#: outside the DYN_WINDOW after each input sample, where it takes RK4 ticks.
STEPS_REF = 400
DYN_WINDOW = 0.05

# fault indices (0-based position in the fault vector)
F1, F2, F3, F4, F5, F6, F7, F8, F9, F10 = range(10)
F11, F12, F13, F14, F15, F16, F17, F18, F19 = range(10, 19)


@njit(cache=True, error_model="numpy")
def _play(y, u, width):
    """Backlash (play operator) of total ``width``: output ``y`` follows ``u`` at +-width/2."""
    h = 0.5 * width
    if u > y + h:
        return u - h
    if u < y - h:
        return u + h
    return y


@njit(cache=True, error_model="numpy")
def _ep(cvi):
    return interp_table(cvi, EP_X, EP_Y)


@njit(cache=True, error_model="numpy")
def _fault(t, idx, strength, onset, ramp):
    if idx < 0 or t < onset:
        return 0.0
    if ramp > 0.0:
        return strength * min(1.0, (t - onset) / ramp)
    return strength


@njit(cache=True, error_model="numpy")
def _simulate_run(u_read, fidx, fstr, fon, framp, scheme, steps, hold, n_warm, par, out, extra):
    """Simulate one run (a numerical kernel, clearer whole than split).

    ``u_read`` (T, 4): CV [0..1] and the readings of P1 [Pa], P2 [Pa], T1 [°C] at 1 Hz, which
    the sensors' calibration in ``par`` (the parameter vector) turns into the true inputs;
    ``hold`` 0: each sample held
    for one second (zero-order hold), 1: linear interpolation between samples (first-order
    hold; the last sample is held). With ``hold=1`` the pressure drop across the valve (the plug
    force) is interpolated linearly, which is exact while P1 >= pv.
    ``out`` (T, 5): noise-free, unclipped measured X', F', P1', P2', T1' (through the sensors'
    calibration).
    ``extra`` (T, 4): true stem position X (fraction), true flow F [t/h], chamber gauge
    pressure Ps [Pa], positioner controller output CVI.
    """
    n_t = u_read.shape[0]
    u = np.empty((n_t, 4))
    for k in range(n_t):
        u[k, 0] = u_read[k, 0]
        u[k, 1] = (u_read[k, 1] - par[IDX_P1_OFFSET] * P_RANGE) / par[IDX_P1_GAIN]
        u[k, 2] = (u_read[k, 2] - par[IDX_P2_OFFSET] * P_RANGE) / par[IDX_P2_GAIN]
        u[k, 3] = (u_read[k, 3] - par[IDX_T1_OFFSET] * T_RANGE) / par[IDX_T1_GAIN]
    tau_sp = par[IDX_TAU]
    area = par[IDX_AREA]
    preload = par[IDX_PRELOAD]
    damping = par[IDX_DAMPING]
    mass = par[IDX_MASS]
    volume0 = par[IDX_VOLUME]
    k_in = par[IDX_K_IN]
    backlash = par[IDX_BACKLASH]
    spring_k = par[IDX_SPRING]
    kp = par[IDX_KP]
    plug_area = par[IDX_PLUG_AREA]
    supply = par[IDX_SUPPLY]
    dt_tick = 1.0 / steps
    ctrl = round(T_CTRL * steps)
    f = np.zeros(19)
    hyd = np.zeros(8)
    hyd_next = np.zeros(8)
    # state
    s1 = 0.0
    s2 = 0.0
    m = par[IDX_M_INIT]
    p = PATM
    xr = 0.0
    v = 0.0
    xb = 0.0  # friction play output (stem before the end-stop clip)
    xfb = 0.0  # feedback play output (f15)
    x_prev = 0.0
    flag_prev = 1
    cvp = 0.0
    cvi = 0.0
    fval_last = np.nan
    a_sp = math.exp(-2.0 * dt_tick / tau_sp)
    b_sp = 2.0 * dt_tick / tau_sp
    # the fast scheme integrates the first DYN_WINDOW s after every input sample (and after an
    # abrupt fault change) with the reference RK4, where the inputs' steps excite the stem's
    # inertia and the chamber's velocity clip; elsewhere it takes quasi-static double steps
    n_dyn = 2 * round(0.5 * DYN_WINDOW * steps)
    tick = 0
    for sec in range(-n_warm, n_t):
        ki = sec if sec > 0 else 0
        kn = ki + 1 if (hold == 1 and sec >= 0 and ki + 1 < n_t) else ki
        cv0 = u[ki, 0]
        dcv = u[kn, 0] - cv0
        cvc = clip_value(cv0, 0.0, 1.024)
        j = 0
        dyn_until = n_dyn
        while j < steps:
            t = sec + j * dt_tick
            fv = _fault(t, fidx, fstr, fon, framp)
            if fidx >= 0:
                f[fidx] = fv
            if j == 0:
                hydraulics(u[ki, 1], u[ki, 2], u[ki, 3], f[F7], f[F17], hyd)
                if kn != ki:
                    hydraulics(u[kn, 1], u[kn, 2], u[kn, 3], f[F7], f[F17], hyd_next)
            elif fv != fval_last:
                if fidx == F7 or fidx == F17:
                    hydraulics(u[ki, 1], u[ki, 2], u[ki, 3], f[F7], f[F17], hyd)
                    if kn != ki:
                        hydraulics(u[kn, 1], u[kn, 2], u[kn, 3], f[F7], f[F17], hyd_next)
                if framp <= 0.0:
                    dyn_until = j + n_dyn
            fval_last = fv
            rk4 = scheme == 0 or j < dyn_until or j % 2 == 1
            dt = dt_tick if rk4 else 2.0 * dt_tick
            if kn != ki:
                # inputs at the step's start (RK4 tick) or its middle (double step)
                w = (j + (0.0 if rk4 else 0.5)) * dt_tick
                cvc = clip_value(cv0 + w * dcv, 0.0, 1.024)
                dp_valve = hyd[7] + (j * dt_tick) * (hyd_next[7] - hyd[7])
            else:
                dp_valve = hyd[7]
            # --- servomotor geometry with faults ---------------------------------------
            hb = clip_value(X0 * (1.0 - 0.2 * f[F2]), 0.0, X0)
            hb = clip_value(hb * (1.0 - f[F1]), 0.0, X0)
            hb = max(hb * (1.0 + 0.1 * f[F3]), 0.0)
            db = clip_value(X0 * (backlash + f[F4]), 0.0, X0)
            dbf = clip_value(db * (1.0 + 0.5 * f[F8] * (1.0 - x_prev / X0)), 0.0, X0)
            aef = area * (1.0 - f[F10])
            kf = spring_k * (1.0 - f[F11])
            xb = _play(xb, xr, dbf)
            x = min(max(xb, 0.0), hb)
            # --- positioner ---------------------------------------------------------------
            xm = clip_value(x * (1.0 + 1.25 * f[F13]), -0.25 * X0, 1.25 * X0)
            xfb = _play(xfb, clip_value(xm, LEVER_MIN, LEVER_MAX), f[F15] * X0)
            if tick % ctrl == 0:
                pv_pos = 0.5 + math.asin((xfb - 0.01905) / 0.0381) * (180.0 / math.pi) / 60.0
                cvi = clip_value(kp * (s2 - pv_pos), -1.0, 1.0)
                cvp = clip_value(_ep(cvi) * (1.0 - f[F12]), -1.0, 1.0)
            # --- outputs at the 1 s sampling instants -----------------------------------
            if j == 0 and sec >= 0:
                flow = total_flow(x / X0, hyd, f[F2], f[F3], f[F5], f[F6], f[F18], par)
                out[sec, 0] = par[IDX_X_GAIN] * (xm / X0) + par[IDX_X_OFFSET]
                out[sec, 1] = (
                    par[IDX_F_GAIN] * (flow / F_RANGE * (1.0 - f[F19])) + par[IDX_F_OFFSET]
                )
                out[sec, 2] = par[IDX_P1_GAIN] * (hyd[0] / P_RANGE) + par[IDX_P1_OFFSET]
                out[sec, 3] = par[IDX_P2_GAIN] * (hyd[1] / P_RANGE) + par[IDX_P2_OFFSET]
                out[sec, 4] = par[IDX_T1_GAIN] * (hyd[2] / T_RANGE) + par[IDX_T1_OFFSET]
                extra[sec, 0] = x / X0
                extra[sec, 1] = flow
                extra[sec, 2] = p - PATM
                extra[sec, 3] = cvi
            # --- valve plug force -------------------------------------------------------
            xv = valve_position(x / X0, f[F2], f[F3])
            fvc = dp_valve / interp_table(100.0 * xv, KM_X, KM_V) * plug_area
            # --- chamber air flow (pressure at the step's start) --------------------------
            ps = p - PATM
            pz = supply * (1.0 - f[F16])
            if pz < PZ_MIN:
                pz = 0.0
            psrc = pz if cvp > 0.0 else 0.0
            dps = psrc - ps
            mdot = k_in * abs(cvp) * math.sqrt(abs(dps))
            if dps < 0.0:
                mdot = -mdot
            leak = f[F9] + f[F10]
            if leak != 0.0:
                mdot -= K_LEAK * leak * math.sqrt(abs(ps))
            vol = volume0 + aef * x
            g0 = mass * GRAV - fvc
            # --- end stops --------------------------------------------------------------
            # contact test with the static force (no damping term): a stem resting on a stop
            # with the net static force into it stays there (v = 0); with the damping term
            # F = Fs - c v tends to 0+ from above while v -> Fs/c, the flag never sets and the
            # stem keeps a phantom velocity that compresses the chamber through the volume law
            force = g0 + aef * ps - kf * (x_prev + preload)
            flag = 0
            if x_prev <= 0.0 and force <= 0.0:
                flag = 1
            elif x >= hb and force > 0.0:
                flag = 2
            if flag != flag_prev:
                v = 0.0
            if rk4:
                # --- RK4 on (s1, s2, m, p, xr, v) ---------------------------------------
                spring = kf * (x_prev + preload)
                k1s1 = (cvc - s1) / tau_sp
                k1s2 = (s1 - s2) / tau_sp
                k1p, k1v = _rhs(p, m, v, mdot, aef, vol, g0, spring, flag, damping, mass)
                k1x = v
                m2 = m + 0.5 * dt * mdot
                s1b = s1 + 0.5 * dt * k1s1
                k2s1 = (cvc - s1b) / tau_sp
                k2s2 = (s1b - (s2 + 0.5 * dt * k1s2)) / tau_sp
                vb = v + 0.5 * dt * k1v
                k2p, k2v = _rhs(
                    p + 0.5 * dt * k1p, m2, vb, mdot, aef, vol, g0, spring, flag, damping, mass
                )
                k2x = vb
                s1c = s1 + 0.5 * dt * k2s1
                k3s1 = (cvc - s1c) / tau_sp
                k3s2 = (s1c - (s2 + 0.5 * dt * k2s2)) / tau_sp
                vc = v + 0.5 * dt * k2v
                k3p, k3v = _rhs(
                    p + 0.5 * dt * k2p, m2, vc, mdot, aef, vol, g0, spring, flag, damping, mass
                )
                k3x = vc
                s1d = s1 + dt * k3s1
                k4s1 = (cvc - s1d) / tau_sp
                k4s2 = (s1d - (s2 + dt * k3s2)) / tau_sp
                vd = v + dt * k3v
                k4p, k4v = _rhs(
                    p + dt * k3p,
                    m + dt * mdot,
                    vd,
                    mdot,
                    aef,
                    vol,
                    g0,
                    spring,
                    flag,
                    damping,
                    mass,
                )
                k4x = vd
                s1 += dt / 6.0 * (k1s1 + 2.0 * k2s1 + 2.0 * k3s1 + k4s1)
                s2 += dt / 6.0 * (k1s2 + 2.0 * k2s2 + 2.0 * k3s2 + k4s2)
                p += dt / 6.0 * (k1p + 2.0 * k2p + 2.0 * k3p + k4p)
                xr += dt / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x)
                v += dt / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v)
                m += dt * mdot
            else:
                # --- fast: exact SP filter, isothermal chamber, quasi-static implicit stem ----
                e1 = s1 - cvc
                e2 = s2 - cvc
                s1 = cvc + e1 * a_sp
                s2 = cvc + (e2 + e1 * b_sp) * a_sp
                m_new = clip_value(m + dt * mdot, 1e-9, M_MAX)
                pm = p * (m_new / m)
                m = m_new
                if flag != 0:
                    v = 0.0
                    p = pm
                else:
                    stiff_p = dt * aef * aef * pm / vol
                    v_new = _stem_velocity(
                        g0 + aef * (pm - PATM),
                        stiff_p,
                        kf,
                        x,
                        xb,
                        xr,
                        dbf,
                        hb,
                        dt,
                        preload,
                        damping,
                    )
                    if abs(v_new) > V_CLIP:
                        # the chamber volume law saturates (|v| > 0.02 m/s): the air spring is
                        # then an explicit, fixed pressure change over the step
                        p_clip = pm * math.exp(-aef * dt * math.copysign(V_CLIP, v_new) / vol)
                        v_new = _stem_velocity(
                            g0 + aef * (p_clip - PATM),
                            0.0,
                            kf,
                            x,
                            xb,
                            xr,
                            dbf,
                            hb,
                            dt,
                            preload,
                            damping,
                        )
                    v = v_new
                    vs = clip_value(v, -V_CLIP, V_CLIP)
                    p = pm * math.exp(-aef * dt * vs / vol)
                    xr += dt * v
            m = clip_value(m, 1e-9, M_MAX)
            p = clip_value(p, 0.0, P_MAX)
            xr = clip_value(xr, -0.05 * X0, 1.25 * X0)
            x_prev = x
            flag_prev = flag
            n_ticks = 1 if rk4 else 2
            tick += n_ticks
            j += n_ticks


@njit(cache=True, error_model="numpy")
def _stem_velocity(base, stiff_p, kf, x, xb, xr, dbf, hb, dt, preload, damping):
    """Linearly implicit Euler velocity of the quasi-static stem over one fast step.

    ``base`` is the force without spring and damping, ``stiff_p`` the air-spring term
    ``dt Ae^2 P / V`` (implicit in the chamber pressure). Inside the play the spring sees the
    held stem position; if the motor position reaches the play's edge within the step the
    spring follows it beyond the edge (implicit too), so the stem does not overshoot.
    """
    v_free = (base - kf * (x + preload)) / (damping + stiff_p)
    h = 0.5 * dbf
    if v_free > 0.0:
        room = xb + h - xr
    else:
        room = xr - (xb - h)
    inside = x == xb and (0.0 < x or v_free > 0.0) and (x < hb or v_free < 0.0)
    if not (inside and abs(v_free) * dt > room):
        return v_free
    edge = xb + h if v_free > 0.0 else xb - h
    v_new = (base - kf * (xb + (xr - edge) + preload)) / (damping + stiff_p + dt * kf)
    if (v_new > 0.0) != (v_free > 0.0):
        return (edge - xr) / dt
    return v_new


@njit(cache=True, error_model="numpy")
def _rhs(p, m, v, mdot, aef, vol, g0, spring, flag, damping, mass):
    vs = clip_value(v, -V_CLIP, V_CLIP)
    dp = p * (mdot / m - aef * vs / vol)
    if flag != 0:
        return dp, 0.0
    return dp, (g0 + aef * (p - PATM) - spring - damping * v) / mass


@njit(parallel=True, cache=True, error_model="numpy")
def simulate_batch(u, fidx, fstr, fon, framp, scheme, steps, hold, n_warm, par, out, extra):
    """Simulate runs in parallel: run ``r`` with inputs ``u[r]``, fault ``fidx[r]`` (-1: none)
    of strength ``fstr[r]``, onset ``fon[r]``, ramp ``framp[r]``, parameter vector ``par[r]``
    (`ActuatorParameters.as_vector`); results in ``out[r]`` and ``extra[r]``."""
    for r in prange(u.shape[0]):
        _simulate_run(
            u[r], fidx[r], fstr[r], fon[r], framp[r], scheme, steps, hold, n_warm, par[r],
            out[r], extra[r],
        )  # fmt: skip
