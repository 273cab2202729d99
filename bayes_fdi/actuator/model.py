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

All arrays are in physical units inside this module (m, Pa, °C, t/h).
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba import njit, prange

# Numba's own thread pool rather than OpenMP: OpenMP-launched kernels set the process-wide
# OpenMP thread count, which torch reads as its own intra-op thread count, so simulating would
# silently change the thread count (and summation order) of every torch model fitted later.
# Users who chose a layer themselves (NUMBA_THREADING_LAYER) keep it.
if numba.config.THREADING_LAYER == "default":
    numba.config.THREADING_LAYER = "workqueue"

__all__ = [
    "PARAMETERS",
    "flow_rate",
    "vapour_pressure",
    "water_density",
]

# --- nominal parameters (DABLib v1.22) ----------------------------------------------------
X0 = 0.0381  # stroke [m]
PATM = 101325.0  # atmospheric pressure [Pa]
R_AIR = 287.0  # gas constant of air [J/(kg K)]
T_AIR = 293.0  # air temperature [K]
V0 = 0.0055  # chamber dead volume [m^3]
AE = 0.029  # effective diaphragm area [m^2]
MASS = 2.0  # moving mass [kg]
GRAV = 9.81  # [m/s^2]
K_SPRING = 60892.0  # spring + diaphragm stiffness [N/m]
X_PRE = 0.009525  # spring preload compression [m]
C_DAMP = 1500.0  # viscous damping [N s/m]
PZ = 600e3  # supply pressure (gauge) [Pa]
PZ_MIN = 120e3  # below this the supply is treated as lost [Pa]
K_IN = 2.5e-6  # chamber inflow coefficient [kg/(s sqrt(Pa))]
K_LEAK = 2e-7  # leak coefficient per unit fault [kg/(s sqrt(Pa))]
P_MAX = 700e3  # chamber pressure clip (absolute) [Pa]
M_MAX = 0.1  # chamber air mass clip [kg]
V_CLIP = 0.02  # stem speed clip in the chamber volume law [m/s]
TAU_SP = 0.30  # set-point filter lags [s]
KP = 100.0  # positioner P gain
T_CTRL = 0.035  # positioner sampling period [s]
LEVER_MIN, LEVER_MAX = -0.01, 0.05  # feedback lever clip [m]
KV_MAX = 120.0  # valve Kv [m^3/h]
KV_BYPASS = 19.75  # bypass Kv [m^3/h]
D_PLUG = 0.05  # plug diameter [m]
A_PLUG = math.pi * D_PLUG**2 / 4.0
P_RANGE = 4e6  # P1', P2' full scale [Pa]
T_RANGE = 200.0  # T1' full scale [°C]
F_RANGE = 40.0  # F' full scale [t/h]
M_INIT = PATM * V0 / (R_AIR * T_AIR)  # initial air mass [kg]

EP_X = np.array([-1.0, -0.94, -0.54, 0.46, 0.86, 1.0])
EP_Y = np.array([-0.55, -0.55, -0.02, 0.02, 1.0, 1.0])
RC_P = np.array([0.0, 1.724, 3.448, 6.895, 13.79, 17.24, 20.69])  # MPa
RC_V = np.array([0.94, 0.87, 0.84, 0.79, 0.75, 0.725, 0.685])
KM_X = np.array([0.0, 10, 20, 30, 40, 50, 60, 70, 80, 90, 99, 100])
KM_V = np.array([1.00, 0.95, 0.90, 0.85, 0.785, 0.725, 0.67, 0.61, 0.555, 0.50, 0.45, 0.40])
KMB_X = np.array([0.0, 10, 20, 30, 40, 50, 60, 70, 80, 90, 100])
KMB_V = np.array([0.45, 0.5, 0.555, 0.61, 0.67, 0.725, 0.785, 0.85, 0.90, 0.95, 1.0])
COMP_T = np.array([0.0, 10.0, 20.0, 50.0, 110.0])
COMP_V = np.array([5.26e-10, 5.02e-10, 4.81e-10, 4.69e-10, 4.42e-10])

#: Nominal parameters (name -> (value, unit, meaning)) for documentation and tests.
PARAMETERS: dict[str, tuple[float, str, str]] = {
    "X0": (X0, "m", "stem stroke"),
    "V0": (V0, "m^3", "chamber dead volume"),
    "Ae": (AE, "m^2", "effective diaphragm area"),
    "m": (MASS, "kg", "moving mass"),
    "k": (K_SPRING, "N/m", "spring + diaphragm stiffness"),
    "x0": (X_PRE, "m", "spring preload (25 % stroke)"),
    "c": (C_DAMP, "N s/m", "viscous damping"),
    "Pz": (PZ, "Pa", "positioner supply pressure (gauge)"),
    "k_in": (K_IN, "kg/(s Pa^0.5)", "chamber inflow coefficient"),
    "k_leak": (K_LEAK, "kg/(s Pa^0.5)", "chamber leak coefficient per unit f9, f10"),
    "tau_sp": (TAU_SP, "s", "each of the two set-point filter lags"),
    "Kp": (KP, "-", "positioner proportional gain"),
    "T_ctrl": (T_CTRL, "s", "positioner sampling period"),
    "Kv": (KV_MAX, "m^3/h", "valve flow coefficient (fully open)"),
    "Kv_bypass": (KV_BYPASS, "m^3/h", "bypass flow coefficient (fully open)"),
    "d_plug": (D_PLUG, "m", "plug diameter (plug force)"),
    "db": (0.01 * X0, "m", "nominal backlash (friction) width, 1 % of stroke"),
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
def _interp(x, xp, fp):
    n = xp.shape[0]
    if x <= xp[0]:
        return fp[0]
    if x >= xp[n - 1]:
        return fp[n - 1]
    i = 1
    while xp[i] < x:
        i += 1
    w = (x - xp[i - 1]) / (xp[i] - xp[i - 1])
    return fp[i - 1] + w * (fp[i] - fp[i - 1])


@njit(cache=True, error_model="numpy")
def _clip(x, lo, hi):
    return lo if x < lo else (hi if x > hi else x)


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
def _vapour_pressure(t):
    return 10.0 ** (10.7167 - 2141.0 / (t + 273.15))


@njit(cache=True, error_model="numpy")
def _water_density(t, p):
    t = _clip(t, 0.0, 110.0)
    if t >= 30.0:
        rho0 = 1000.0 - (t - 4.0) ** 2 * (t + 273.0) * 1000.0 * (350.0 - t) / (
            466700.0 * (t + 67.0) * (365.0 - t)
        )
    else:
        rho0 = 1000.0 - (t - 4.0) ** 2 * (t + 283.0) * 1000.0 / (503570.0 * (t + 67.2))
    return rho0 / (1.0 - _interp(t, COMP_T, COMP_V) * p)


@njit(cache=True, error_model="numpy")
def _hydraulics(p1, p2, t1, f7, f17, out):
    """External faults on the inputs and the valve's pressure/medium algebra.

    ``out`` receives: P1f, P2f, T1f (faulted, what P1', P2', T1' show), pv, P1e, rc, rho, dP.
    """
    if f17 < 0.0:
        p1 = _clip(p1 * (1.0 - abs(f17)), 0.0, P_RANGE)
    elif f17 > 0.0:
        p2 = _clip(p2 * (1.0 - f17), 0.0, P_RANGE)
    t1f = _clip(t1, 0.0, 200.0) + 100.0 * f7
    if f7 > 0.0:
        t1f += 200.0
    t1f = min(t1f, 300.0)
    pv = _vapour_pressure(t1f)
    p1e = max(p1, pv)
    out[0] = p1
    out[1] = p2
    out[2] = t1f
    out[3] = pv
    out[4] = p1e
    out[5] = _interp(p1e * 1e-6, RC_P, RC_V)
    out[6] = _water_density(t1f, p1e)
    out[7] = p1e - p2


@njit(cache=True, error_model="numpy")
def _valve_position(x_frac, f2, f3):
    xv = _clip(x_frac + 0.2 * f2, 0.0, 1.0)
    return _clip(xv - 0.1 * f3, 0.0, 1.0)


@njit(cache=True, error_model="numpy")
def _choked(dp, km, p1e, rc, pv):
    dp_allow = max(0.0, km * (p1e - rc * pv))
    dp_eff = dp if dp_allow > dp else dp_allow
    return max(dp_eff, 0.0)  # no reverse flow through the valve (P1 < P2)


@njit(cache=True, error_model="numpy")
def _flow(x_frac, hyd, f2, f3, f5, f6, f18):
    """Total flow [t/h] through valve and bypass at stem position ``x_frac`` (closing)."""
    p1e, rc, pv, rho, dp = hyd[4], hyd[5], hyd[3], hyd[6], hyd[7]
    xv = _valve_position(x_frac, f2, f3)
    if xv <= 0.975:
        kvr = math.exp(-5.0 * xv)
    else:
        kvr = math.exp(-4.875) * (1.0 - xv) / 0.025
    kvr = _clip(kvr * (1.0 - 0.2 * f2) * (1.0 + 0.1 * f3), 0.0, 1.0) + 0.1 * f6
    km = _interp(100.0 * xv, KM_X, KM_V)
    dpe = _choked(dp, km, p1e, rc, pv)
    q = 100.0 * KV_MAX * kvr * math.sqrt(dpe * 1e-6 / rho)
    fv = q * rho / 1000.0 * (1.0 - 0.05 * f5)
    xb = 1.0 - f18
    kvb = KV_BYPASS * (1.0 - xb)
    kmb = _interp(100.0 * xb, KMB_X, KMB_V)
    dpeb = _choked(dp, kmb, p1e, rc, pv)
    qb = 100.0 * kvb * math.sqrt(dpeb * 1e-6 / 1000.0)
    return fv + qb


@njit(cache=True, error_model="numpy")
def _ep(cvi):
    return _interp(cvi, EP_X, EP_Y)


@njit(cache=True, error_model="numpy")
def _fault(t, idx, strength, onset, ramp):
    if idx < 0 or t < onset:
        return 0.0
    if ramp > 0.0:
        return strength * min(1.0, (t - onset) / ramp)
    return strength


@njit(cache=True, error_model="numpy")
def _simulate_run(u, fidx, fstr, fon, framp, scheme, steps, hold, n_warm, out, extra):
    """Simulate one run.

    ``u`` (T, 4): CV [0..1], P1 [Pa], P2 [Pa], T1 [°C] at 1 Hz; ``hold`` 0: each sample held
    for one second (zero-order hold), 1: linear interpolation between samples (first-order
    hold; the last sample is held). With ``hold=1`` the pressure drop across the valve (the plug
    force) is interpolated linearly, which is exact while P1 >= pv.
    ``out`` (T, 5): noise-free, unclipped measured X', F', P1', P2', T1'.
    ``extra`` (T, 4): true stem position X (fraction), true flow F [t/h], chamber gauge
    pressure Ps [Pa], positioner controller output CVI.
    """
    n_t = u.shape[0]
    dt_tick = 1.0 / steps
    ctrl = round(T_CTRL * steps)
    f = np.zeros(19)
    hyd = np.zeros(8)
    hyd_next = np.zeros(8)
    # state
    s1 = 0.0
    s2 = 0.0
    m = M_INIT
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
    a_sp = math.exp(-2.0 * dt_tick / TAU_SP)
    b_sp = 2.0 * dt_tick / TAU_SP
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
        cvc = _clip(cv0, 0.0, 1.024)
        j = 0
        dyn_until = n_dyn
        while j < steps:
            t = sec + j * dt_tick
            fv = _fault(t, fidx, fstr, fon, framp)
            if fidx >= 0:
                f[fidx] = fv
            if j == 0:
                _hydraulics(u[ki, 1], u[ki, 2], u[ki, 3], f[F7], f[F17], hyd)
                if kn != ki:
                    _hydraulics(u[kn, 1], u[kn, 2], u[kn, 3], f[F7], f[F17], hyd_next)
            elif fv != fval_last:
                if fidx == F7 or fidx == F17:
                    _hydraulics(u[ki, 1], u[ki, 2], u[ki, 3], f[F7], f[F17], hyd)
                    if kn != ki:
                        _hydraulics(u[kn, 1], u[kn, 2], u[kn, 3], f[F7], f[F17], hyd_next)
                if framp <= 0.0:
                    dyn_until = j + n_dyn
            fval_last = fv
            rk4 = scheme == 0 or j < dyn_until or j % 2 == 1
            dt = dt_tick if rk4 else 2.0 * dt_tick
            if kn != ki:
                # inputs at the step's start (RK4 tick) or its middle (double step)
                w = (j + (0.0 if rk4 else 0.5)) * dt_tick
                cvc = _clip(cv0 + w * dcv, 0.0, 1.024)
                dp_valve = hyd[7] + (j * dt_tick) * (hyd_next[7] - hyd[7])
            else:
                dp_valve = hyd[7]
            # --- servomotor geometry with faults ---------------------------------------
            hb = _clip(X0 * (1.0 - 0.2 * f[F2]), 0.0, X0)
            hb = _clip(hb * (1.0 - f[F1]), 0.0, X0)
            hb = max(hb * (1.0 + 0.1 * f[F3]), 0.0)
            db = _clip(X0 * (0.01 + f[F4]), 0.0, X0)
            dbf = _clip(db * (1.0 + 0.5 * f[F8] * (1.0 - x_prev / X0)), 0.0, X0)
            aef = AE * (1.0 - f[F10])
            kf = K_SPRING * (1.0 - f[F11])
            xb = _play(xb, xr, dbf)
            x = min(max(xb, 0.0), hb)
            # --- positioner ---------------------------------------------------------------
            xm = _clip(x * (1.0 + 1.25 * f[F13]), -0.25 * X0, 1.25 * X0)
            xfb = _play(xfb, _clip(xm, LEVER_MIN, LEVER_MAX), f[F15] * X0)
            if tick % ctrl == 0:
                pv_pos = 0.5 + math.asin((xfb - 0.01905) / 0.0381) * (180.0 / math.pi) / 60.0
                cvi = _clip(KP * (s2 - pv_pos), -1.0, 1.0)
                cvp = _clip(_ep(cvi) * (1.0 - f[F12]), -1.0, 1.0)
            # --- outputs at the 1 s sampling instants -----------------------------------
            if j == 0 and sec >= 0:
                flow = _flow(x / X0, hyd, f[F2], f[F3], f[F5], f[F6], f[F18])
                out[sec, 0] = xm / X0
                out[sec, 1] = flow / F_RANGE * (1.0 - f[F19])
                out[sec, 2] = hyd[0] / P_RANGE
                out[sec, 3] = hyd[1] / P_RANGE
                out[sec, 4] = hyd[2] / T_RANGE
                extra[sec, 0] = x / X0
                extra[sec, 1] = flow
                extra[sec, 2] = p - PATM
                extra[sec, 3] = cvi
            # --- valve plug force -------------------------------------------------------
            xv = _valve_position(x / X0, f[F2], f[F3])
            fvc = dp_valve / _interp(100.0 * xv, KM_X, KM_V) * A_PLUG
            # --- chamber air flow (pressure at the step's start) --------------------------
            ps = p - PATM
            pz = PZ * (1.0 - f[F16])
            if pz < PZ_MIN:
                pz = 0.0
            psrc = pz if cvp > 0.0 else 0.0
            dps = psrc - ps
            mdot = K_IN * abs(cvp) * math.sqrt(abs(dps))
            if dps < 0.0:
                mdot = -mdot
            leak = f[F9] + f[F10]
            if leak != 0.0:
                mdot -= K_LEAK * leak * math.sqrt(abs(ps))
            vol = V0 + aef * x
            g0 = MASS * GRAV - fvc
            # --- end stops --------------------------------------------------------------
            # contact test with the static force (no damping term): a stem resting on a stop
            # with the net static force into it stays there (v = 0); with the damping term
            # F = Fs - c v tends to 0+ from above while v -> Fs/c, the flag never sets and the
            # stem keeps a phantom velocity that compresses the chamber through the volume law
            force = g0 + aef * ps - kf * (x_prev + X_PRE)
            flag = 0
            if x_prev <= 0.0 and force <= 0.0:
                flag = 1
            elif x >= hb and force > 0.0:
                flag = 2
            if flag != flag_prev:
                v = 0.0
            if rk4:
                # --- RK4 on (s1, s2, m, p, xr, v) ---------------------------------------
                spring = kf * (x_prev + X_PRE)
                k1s1 = (cvc - s1) / TAU_SP
                k1s2 = (s1 - s2) / TAU_SP
                k1p, k1v = _rhs(p, m, v, mdot, aef, vol, g0, spring, flag)
                k1x = v
                m2 = m + 0.5 * dt * mdot
                s1b = s1 + 0.5 * dt * k1s1
                k2s1 = (cvc - s1b) / TAU_SP
                k2s2 = (s1b - (s2 + 0.5 * dt * k1s2)) / TAU_SP
                vb = v + 0.5 * dt * k1v
                k2p, k2v = _rhs(p + 0.5 * dt * k1p, m2, vb, mdot, aef, vol, g0, spring, flag)
                k2x = vb
                s1c = s1 + 0.5 * dt * k2s1
                k3s1 = (cvc - s1c) / TAU_SP
                k3s2 = (s1c - (s2 + 0.5 * dt * k2s2)) / TAU_SP
                vc = v + 0.5 * dt * k2v
                k3p, k3v = _rhs(p + 0.5 * dt * k2p, m2, vc, mdot, aef, vol, g0, spring, flag)
                k3x = vc
                s1d = s1 + dt * k3s1
                k4s1 = (cvc - s1d) / TAU_SP
                k4s2 = (s1d - (s2 + dt * k3s2)) / TAU_SP
                vd = v + dt * k3v
                k4p, k4v = _rhs(p + dt * k3p, m + dt * mdot, vd, mdot, aef, vol, g0, spring, flag)
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
                m_new = _clip(m + dt * mdot, 1e-9, M_MAX)
                pm = p * (m_new / m)
                m = m_new
                if flag != 0:
                    v = 0.0
                    p = pm
                else:
                    stiff_p = dt * aef * aef * pm / vol
                    v_new = _stem_velocity(
                        g0 + aef * (pm - PATM), stiff_p, kf, x, xb, xr, dbf, hb, dt
                    )
                    if abs(v_new) > V_CLIP:
                        # the chamber volume law saturates (|v| > 0.02 m/s): the air spring is
                        # then an explicit, fixed pressure change over the step
                        p_clip = pm * math.exp(-aef * dt * math.copysign(V_CLIP, v_new) / vol)
                        v_new = _stem_velocity(
                            g0 + aef * (p_clip - PATM), 0.0, kf, x, xb, xr, dbf, hb, dt
                        )
                    v = v_new
                    vs = _clip(v, -V_CLIP, V_CLIP)
                    p = pm * math.exp(-aef * dt * vs / vol)
                    xr += dt * v
            m = _clip(m, 1e-9, M_MAX)
            p = _clip(p, 0.0, P_MAX)
            xr = _clip(xr, -0.05 * X0, 1.25 * X0)
            x_prev = x
            flag_prev = flag
            n_ticks = 1 if rk4 else 2
            tick += n_ticks
            j += n_ticks


@njit(cache=True, error_model="numpy")
def _stem_velocity(base, stiff_p, kf, x, xb, xr, dbf, hb, dt):
    """Linearly implicit Euler velocity of the quasi-static stem over one fast step.

    ``base`` is the force without spring and damping, ``stiff_p`` the air-spring term
    ``dt Ae^2 P / V`` (implicit in the chamber pressure). Inside the play the spring sees the
    held stem position; if the motor position reaches the play's edge within the step the
    spring follows it beyond the edge (implicit too), so the stem does not overshoot.
    """
    v_free = (base - kf * (x + X_PRE)) / (C_DAMP + stiff_p)
    h = 0.5 * dbf
    if v_free > 0.0:
        room = xb + h - xr
    else:
        room = xr - (xb - h)
    inside = x == xb and (0.0 < x or v_free > 0.0) and (x < hb or v_free < 0.0)
    if not (inside and abs(v_free) * dt > room):
        return v_free
    edge = xb + h if v_free > 0.0 else xb - h
    v_new = (base - kf * (xb + (xr - edge) + X_PRE)) / (C_DAMP + stiff_p + dt * kf)
    if (v_new > 0.0) != (v_free > 0.0):
        return (edge - xr) / dt
    return v_new


@njit(cache=True, error_model="numpy")
def _rhs(p, m, v, mdot, aef, vol, g0, spring, flag):
    vs = _clip(v, -V_CLIP, V_CLIP)
    dp = p * (mdot / m - aef * vs / vol)
    if flag != 0:
        return dp, 0.0
    return dp, (g0 + aef * (p - PATM) - spring - C_DAMP * v) / MASS


@njit(parallel=True, cache=True, error_model="numpy")
def _simulate_batch(u, fidx, fstr, fon, framp, scheme, steps, hold, n_warm, out, extra):
    for r in prange(u.shape[0]):
        _simulate_run(
            u[r], fidx[r], fstr[r], fon[r], framp[r], scheme, steps, hold, n_warm, out[r], extra[r]
        )


@njit(cache=True, error_model="numpy")
def _flow_array(x, p1, p2, t1, f2, f3, f5, f6, f7, f17, f18, out):
    hyd = np.zeros(8)
    for i in range(x.shape[0]):
        _hydraulics(p1[i], p2[i], t1[i], f7, f17, hyd)
        out[i] = _flow(x[i], hyd, f2, f3, f5, f6, f18)


def flow_rate(x, p1, p2, t1, *, faults: dict[str, float] | None = None) -> np.ndarray:
    """Water flow [t/h] through the valve and bypass (the model's flow law, steady state).

    Parameters
    ----------
    x
        Stem position as a fraction of closing (0 = fully open, 1 = closed).
    p1, p2
        Inlet and outlet pressure [Pa].
    t1
        Water temperature [°C].
    faults
        Optional fault values by name among ``f2, f3, f5, f6, f7, f17, f18`` (the faults that
        act on the flow law); f17 and f7 act on the inputs as in the simulator.

    Returns
    -------
    numpy.ndarray
        Flow in t/h, broadcast shape of the inputs.
    """
    faults = dict(faults or {})
    allowed = {"f2", "f3", "f5", "f6", "f7", "f17", "f18"}
    unknown = set(faults) - allowed
    if unknown:
        raise ValueError(f"flow_rate: faults {sorted(unknown)} do not act on the flow law")
    arrays = np.broadcast_arrays(*(np.asarray(a, dtype=np.float64) for a in (x, p1, p2, t1)))
    flat = [np.ascontiguousarray(a.ravel()) for a in arrays]
    out = np.empty(flat[0].shape[0])
    g = {k: float(faults.get(k, 0.0)) for k in allowed}
    _flow_array(*flat, g["f2"], g["f3"], g["f5"], g["f6"], g["f7"], g["f17"], g["f18"], out)
    return out.reshape(arrays[0].shape)


def vapour_pressure(t):
    """Vapour pressure of water [Pa] at temperature ``t`` [°C] (the model's Antoine law)."""
    return 10.0 ** (10.7167 - 2141.0 / (np.asarray(t, dtype=np.float64) + 273.15))


def water_density(t, p=0.0):
    """Density of water [kg/m^3] at ``t`` [°C] (clipped to 0..110) and pressure ``p`` [Pa]."""
    t_arr, p_arr = np.broadcast_arrays(
        np.asarray(t, dtype=np.float64), np.asarray(p, dtype=np.float64)
    )
    pairs = zip(t_arr.ravel(), p_arr.ravel(), strict=True)
    out = np.array([_water_density(a, b) for a, b in pairs])
    return out.reshape(t_arr.shape)
