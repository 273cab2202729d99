"""A second start for the twin's mode search: the valve's flow law fitted to the recorded flow.

The mode search (`bayes_fdi.twin.laplace.fit_laplace`) is local, and its first start, the
priors' medians, can lie in the basin of a wrong mode when a valve differs much from the
nominal one: along the ridge where ``kv exp(-characteristic x)`` keeps the flow at the valve's
usual opening, a steeper characteristic with a large F' zero and a strongly correlated residual
can explain the recorded flow about as well locally, and the search stops there. The flow law is
static, ``F' = f_gain F(x, P1, P2, T1; kv, characteristic) / F_RANGE + f_offset`` at the stem
position ``x`` the X' reading gives, so a grid over the priors of ``kv`` and ``characteristic``
(with the F' zero at its least-squares value, clipped to its prior) finds that basin without
simulating the actuator. `bayes_fdi.twin.twin.ActuatorTwin` searches from both starts and keeps
the higher posterior density.

Written by hand: a grid search of a two-parameter law; its sums are numpy's own (pairwise, in a
fixed order) so that the start, like the posterior, is the same on every machine.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from bayes_fdi.actuator import ActuatorParameters, flow_rate
from bayes_fdi.actuator.excitation import P_RANGE, T_RANGE
from bayes_fdi.actuator.parameters import F_RANGE
from bayes_fdi.twin.priors import ParameterPrior
from bayes_fdi.twin.simulator import FitWindows

__all__ = ["FLOW_LAW_PARAMETERS", "flow_law_start"]

#: the parameters the flow-law start sets (the F' zero only when it is fitted)
FLOW_LAW_PARAMETERS: tuple[str, ...] = ("kv", "characteristic", "f_offset")

#: readings of F' within this distance of the ends of its range are left out of the grid's sum
#: (a reading at the range's end says only that the flow is beyond it)
RANGE_MARGIN = 0.005


def flow_law_start(
    windows: FitWindows,
    base: ActuatorParameters,
    priors: Mapping[str, ParameterPrior],
    *,
    points: int = 41,
    span: float = 3.0,
) -> dict[str, float] | None:
    """Values of ``kv``, ``characteristic`` (and ``f_offset``) that fit the flow law best.

    Parameters
    ----------
    windows
        The fit windows: recorded X', F', P1', P2', T1' of the samples that count.
    base
        The parameters the flow law reads otherwise (the X' and F' sensors' gains and zeros
        that are not fitted, the bypass).
    priors
        The twin's priors: the grid spans ``points`` values of each prior's unconstrained
        variable within ``span`` prior standard deviations of its median.
    points, span
        Size and reach of the grid.

    Returns
    -------
    dict or None
        The fitted values by name; None when ``kv`` or ``characteristic`` is not fitted or
        fewer than 60 readings lie inside F's range.
    """
    if "kv" not in priors or "characteristic" not in priors:
        return None
    mask = windows.mask
    x_reading = windows.observed[..., 0][mask]
    f_reading = windows.observed[..., 1][mask]
    inside = (f_reading > RANGE_MARGIN) & (f_reading < 1.0 - RANGE_MARGIN)
    if int(inside.sum()) < 60:
        return None
    pick = {c: windows.inputs[c].transpose("run", "time").values[mask][inside] for c in
            ("P1", "P2", "T1")}  # fmt: skip
    x_offset = base.x_offset if "x_offset" not in priors else priors["x_offset"].nominal
    x_gain = base.x_gain if "x_gain" not in priors else priors["x_gain"].nominal
    position = np.clip((x_reading[inside] - x_offset) / x_gain, 0.0, 1.0)
    f_reading = f_reading[inside]
    offset_prior = priors.get("f_offset")
    best = (np.inf, 0.0, 0.0, base.f_offset)
    for kv in _grid(priors["kv"], points, span):
        for characteristic in _grid(priors["characteristic"], points, span):
            law = base._replace(kv=float(kv), characteristic=float(characteristic))
            flow = flow_rate(
                position, pick["P1"] * P_RANGE, pick["P2"] * P_RANGE, pick["T1"] * T_RANGE,
                parameters=law,
            )  # fmt: skip
            model = base.f_gain * flow / F_RANGE
            offset = base.f_offset
            if offset_prior is not None:
                offset = float(np.clip(np.mean(f_reading - model), offset_prior.low,
                                       offset_prior.high))  # fmt: skip
            sse = float(np.sum((f_reading - model - offset) ** 2))
            if sse < best[0]:
                best = (sse, float(kv), float(characteristic), offset)
    out = {"kv": best[1], "characteristic": best[2]}
    if offset_prior is not None:
        out["f_offset"] = best[3]
    return out


def _grid(prior: ParameterPrior, points: int, span: float) -> np.ndarray:
    """``points`` values of ``prior`` evenly spaced in its unconstrained variable."""
    z = prior.loc() + prior.spread * np.linspace(-span, span, int(points))
    return prior.to_value(z)
