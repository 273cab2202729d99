"""The valve's water side, compiled with numba: what DABLib's valve and bypass blocks compute.

External faults on the inputs (f17 on P1 or P2, f7 on T1), the water's vapour pressure and
density, the critical pressure ratio and pressure recovery tables, choked flow, and the flow
through the equal-percentage valve and the bypass (`total_flow`); the steady-state laws
`flow_rate`, `water_density` and `vapour_pressure` for checks and plots. Written by hand: these
are DABLib's own equations (Bartyś & Syfert, 2002), which no library implements. Pressures in
Pa, temperatures in °C, flows in t/h.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numba import njit

from bayes_fdi.actuator.parameters import (
    IDX_CHARACTERISTIC,
    IDX_KV,
    IDX_KV_BYPASS,
    IDX_KVR_KNEE,
    P_RANGE,
    parameter_matrix,
)

__all__ = ["compiled_water_density", "flow_rate", "vapour_pressure", "water_density"]

RC_P = np.array([0.0, 1.724, 3.448, 6.895, 13.79, 17.24, 20.69])  # MPa
RC_V = np.array([0.94, 0.87, 0.84, 0.79, 0.75, 0.725, 0.685])
KM_X = np.array([0.0, 10, 20, 30, 40, 50, 60, 70, 80, 90, 99, 100])
KM_V = np.array([1.00, 0.95, 0.90, 0.85, 0.785, 0.725, 0.67, 0.61, 0.555, 0.50, 0.45, 0.40])
KMB_X = np.array([0.0, 10, 20, 30, 40, 50, 60, 70, 80, 90, 100])
KMB_V = np.array([0.45, 0.5, 0.555, 0.61, 0.67, 0.725, 0.785, 0.85, 0.90, 0.95, 1.0])
COMP_T = np.array([0.0, 10.0, 20.0, 50.0, 110.0])
COMP_V = np.array([5.26e-10, 5.02e-10, 4.81e-10, 4.69e-10, 4.42e-10])


@njit(cache=True, error_model="numpy")
def interp_table(x, xp, fp):
    """Piecewise-linear table ``fp(xp)`` at ``x``, held constant beyond its ends."""
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
def clip_value(x, lo, hi):
    """``x`` clipped to ``[lo, hi]``."""
    return lo if x < lo else (hi if x > hi else x)


@njit(cache=True, error_model="numpy")
def _vapour_pressure(t):
    return 10.0 ** (10.7167 - 2141.0 / (t + 273.15))


@njit(cache=True, error_model="numpy")
def _water_density(t, p):
    t = clip_value(t, 0.0, 110.0)
    if t >= 30.0:
        rho0 = 1000.0 - (t - 4.0) ** 2 * (t + 273.0) * 1000.0 * (350.0 - t) / (
            466700.0 * (t + 67.0) * (365.0 - t)
        )
    else:
        rho0 = 1000.0 - (t - 4.0) ** 2 * (t + 283.0) * 1000.0 / (503570.0 * (t + 67.2))
    return rho0 / (1.0 - interp_table(t, COMP_T, COMP_V) * p)


#: `water_density` of one temperature [°C] and pressure [Pa] as a compiled function, for other
#: compiled code (the normal models' valve law).
compiled_water_density = _water_density


@njit(cache=True, error_model="numpy")
def hydraulics(p1, p2, t1, f7, f17, out):
    """External faults on the inputs and the valve's pressure/medium algebra.

    ``out`` receives: P1f, P2f, T1f (faulted, what P1', P2', T1' show), pv, P1e, rc, rho, dP.
    """
    if f17 < 0.0:
        p1 = clip_value(p1 * (1.0 - abs(f17)), 0.0, P_RANGE)
    elif f17 > 0.0:
        p2 = clip_value(p2 * (1.0 - f17), 0.0, P_RANGE)
    t1f = clip_value(t1, 0.0, 200.0) + 100.0 * f7
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
    out[5] = interp_table(p1e * 1e-6, RC_P, RC_V)
    out[6] = _water_density(t1f, p1e)
    out[7] = p1e - p2


@njit(cache=True, error_model="numpy")
def valve_position(x_frac, f2, f3):
    """Valve opening seen by the flow law: stem position moved by sedimentation and erosion."""
    xv = clip_value(x_frac + 0.2 * f2, 0.0, 1.0)
    return clip_value(xv - 0.1 * f3, 0.0, 1.0)


@njit(cache=True, error_model="numpy")
def _choked(dp, km, p1e, rc, pv):
    dp_allow = max(0.0, km * (p1e - rc * pv))
    dp_eff = dp if dp_allow > dp else dp_allow
    return max(dp_eff, 0.0)  # no reverse flow through the valve (P1 < P2)


@njit(cache=True, error_model="numpy")
def total_flow(x_frac, hyd, f2, f3, f5, f6, f18, par):
    """Total flow [t/h] through valve and bypass at stem position ``x_frac`` (closing)."""
    p1e, rc, pv, rho, dp = hyd[4], hyd[5], hyd[3], hyd[6], hyd[7]
    xv = valve_position(x_frac, f2, f3)
    if xv <= 0.975:
        kvr = math.exp(-par[IDX_CHARACTERISTIC] * xv)
    else:
        kvr = par[IDX_KVR_KNEE] * (1.0 - xv) / 0.025
    kvr = clip_value(kvr * (1.0 - 0.2 * f2) * (1.0 + 0.1 * f3), 0.0, 1.0) + 0.1 * f6
    km = interp_table(100.0 * xv, KM_X, KM_V)
    dpe = _choked(dp, km, p1e, rc, pv)
    q = 100.0 * par[IDX_KV] * kvr * math.sqrt(dpe * 1e-6 / rho)
    fv = q * rho / 1000.0 * (1.0 - 0.05 * f5)
    xb = 1.0 - f18
    kvb = par[IDX_KV_BYPASS] * (1.0 - xb)
    kmb = interp_table(100.0 * xb, KMB_X, KMB_V)
    dpeb = _choked(dp, kmb, p1e, rc, pv)
    qb = 100.0 * kvb * math.sqrt(dpeb * 1e-6 / 1000.0)
    return fv + qb


@njit(cache=True, error_model="numpy")
def _flow_array(x, p1, p2, t1, f2, f3, f5, f6, f7, f17, f18, par, out):
    hyd = np.zeros(8)
    for i in range(x.shape[0]):
        hydraulics(p1[i], p2[i], t1[i], f7, f17, hyd)
        out[i] = total_flow(x[i], hyd, f2, f3, f5, f6, f18, par)


def flow_rate(
    x, p1, p2, t1, *, faults: dict[str, float] | None = None, parameters: Any = None
) -> np.ndarray:
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
    parameters
        An `ActuatorParameters` (None: the nominal one); the flow law reads ``kv``,
        ``characteristic`` and ``kv_bypass`` (the true flow: the F' sensor's calibration does
        not apply).

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
    par = parameter_matrix(parameters, 1, "flow_rate")[0]
    _flow_array(*flat, g["f2"], g["f3"], g["f5"], g["f6"], g["f7"], g["f17"], g["f18"], par, out)
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
