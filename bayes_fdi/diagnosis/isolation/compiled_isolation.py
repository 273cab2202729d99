"""The per-second isolation compiled: classifier probabilities, recalibrated group sums, novelty.

`isolate_rows` (the k-means tree of RVCs, `~bayes_fdi.diagnosis.isolation.compiled_tree`) and
`isolate_forest_rows` (the random forest, `~bayes_fdi.diagnosis.isolation.forest`) give, row by
row, what `~bayes_fdi.diagnosis.isolation.isolator.FaultIsolator.run` gives: the classifier's
fault probabilities, their sums over the isolability groups recalibrated by a temperature (one,
or one per age bin of the signature as `~bayes_fdi.calibration.AgeTemperatureScaler`; possibly
followed by the beta map of the top group of `~bayes_fdi.calibration.TopLabelScaler`) and shared
back to the faults in proportion, and the class-novelty score. One compiled pass with
a fixed summation order, so a row's numbers never depend on the rows around it nor on the BLAS
library: the same in ``update``, ``run`` and any chunking of a stream.

Written by hand: no library evaluates these per sample in a fixed order.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numba import njit

from bayes_fdi.diagnosis.isolation.class_novelty import NoveltyArrays, novelty_score_row
from bayes_fdi.diagnosis.isolation.compiled_tree import tree_proba
from bayes_fdi.diagnosis.isolation.forest import forest_proba

__all__ = [
    "IsolationParams",
    "isolate_forest_rows",
    "isolate_rows",
    "map_top",
    "posterior_row",
    "row_temperature",
]


class IsolationParams(NamedTuple):
    """The fitted values `isolate_rows` and `isolate_forest_rows` take."""

    classifier: Any  #: the compiled classifier: `TreeArrays` or `ForestArrays`
    group_of: np.ndarray  #: ``(n_faults,)`` int64: the group of each fault
    n_groups: int
    temperatures: np.ndarray  #: ``(n_bins,)`` temperature of each age bin; ``(0,)``: none
    age_edges: np.ndarray  #: ``(n_bins - 1,)`` upper edges (seconds) of the age bins
    floor: float  #: smallest group probability before taking its logarithm
    top_map: np.ndarray  #: ``(3,)`` beta map of the top group after the temperature, or ``(0,)``
    novelty: NoveltyArrays  #: the class novelty


@njit(cache=True, error_model="numpy")
def map_top(q, coef):  # pragma: no cover - compiled
    """`bayes_fdi.calibration.top_label.top_label_map` of one row ``q``, in place."""
    top, p1, p2 = 0, -np.inf, -np.inf
    for g in range(q.size):
        if q[g] > p1:
            top, p2, p1 = g, p1, q[g]
        elif q[g] > p2:
            p2 = q[g]
    edge = 1e-12
    p = min(max(p1, edge), 1.0 - edge)
    new = 1.0 / (1.0 + math.exp(-(coef[0] * math.log(p) - coef[1] * math.log1p(-p) + coef[2])))
    if p2 > 0.0:  # the top stays on top (TIE_MARGIN of top_label)
        new = max(new, min(p2 / (1.0 - p1 + p2) * (1.0 + 1e-9), p1))
    rest = 0.0
    for g in range(q.size):
        if g != top:
            rest += q[g]
    for g in range(q.size):
        if g == top:
            continue
        q[g] = (q[g] / rest if rest > 0.0 else 1.0 / (q.size - 1)) * (1.0 - new)
    q[top] = new


@njit(cache=True, error_model="numpy")
def row_temperature(params, age):  # pragma: no cover - compiled
    """The temperature of a row whose signature is ``age`` seconds old (0.0: no scaling)."""
    if params.temperatures.size == 0:
        return 0.0
    # the bin as `~bayes_fdi.calibration.age_temperature.age_bins` finds it
    return params.temperatures[np.searchsorted(params.age_edges, age, side="right")]


@njit(cache=True, error_model="numpy")
def posterior_row(p, params, temperature, gp, gq, fq):  # pragma: no cover - compiled
    """Group sums of fault probabilities ``p``, scaled by ``temperature`` (0.0: not scaled),
    shared back to faults."""
    group_of, n_groups = params.group_of, params.n_groups
    floor = params.floor
    for g in range(n_groups):
        gp[g] = 0.0
    for f in range(p.size):
        gp[group_of[f]] += p[f]
    if temperature > 0.0:
        top = -np.inf
        for g in range(n_groups):
            gq[g] = math.log(max(gp[g], floor)) / temperature
            if gq[g] > top:
                top = gq[g]
        total = 0.0
        for g in range(n_groups):
            gq[g] = math.exp(gq[g] - top)
            total += gq[g]
        for g in range(n_groups):
            gq[g] /= total
    else:
        for g in range(n_groups):
            gq[g] = gp[g]
    if params.top_map.size == 3:
        map_top(gq, params.top_map)
    for f in range(p.size):
        g = group_of[f]
        fq[f] = gq[g] * p[f] / gp[g] if gp[g] > 0.0 else gq[g]


@njit(cache=True, error_model="numpy")
def isolate_rows(feats, ages, params, out_fault, out_group, out_nov):  # pragma: no cover
    """Per row of ``feats`` (signatures ``ages`` seconds old): the tree's probabilities,
    calibrated group and fault probabilities and novelty under ``params`` (`IsolationParams` of
    `TreeArrays`); NaN for a row with a non-finite entry."""
    tree = params.classifier
    width = 1
    for n in range(tree.woffsets.size - 1):
        width = max(width, tree.woffsets[n + 1] - tree.woffsets[n])
    phi = np.empty(width)
    right = np.empty(tree.offsets.size - 1)
    z = np.empty(feats.shape[1])
    p = np.empty(out_fault.shape[1])
    gp = np.empty(out_group.shape[1])
    for t in range(feats.shape[0]):
        if _missing(t, feats, out_fault, out_group, out_nov):
            continue
        tree_proba(feats[t], tree, phi, right, z, p)
        _finish_row(t, feats[t], ages[t], p, params, gp, out_fault, out_group, out_nov)


@njit(cache=True, error_model="numpy")
def isolate_forest_rows(feats, ages, params, out_fault, out_group, out_nov):  # pragma: no cover
    """`isolate_rows` with a forest: ``params`` is an `IsolationParams` of `ForestArrays`."""
    p = np.empty(out_fault.shape[1])
    gp = np.empty(out_group.shape[1])
    for t in range(feats.shape[0]):
        if _missing(t, feats, out_fault, out_group, out_nov):
            continue
        forest_proba(feats[t], params.classifier, p)
        _finish_row(t, feats[t], ages[t], p, params, gp, out_fault, out_group, out_nov)


@njit(cache=True)
def _missing(t, feats, out_fault, out_group, out_nov):  # pragma: no cover - compiled
    """Whether row ``t`` has a non-finite entry (no signature), its outputs then set to NaN."""
    for j in range(feats.shape[1]):
        if not np.isfinite(feats[t, j]):
            out_fault[t, :] = np.nan
            out_group[t, :] = np.nan
            out_nov[t] = np.nan
            return True
    return False


@njit(cache=True, error_model="numpy")
def _finish_row(t, row, age, p, params, gp, out_fault, out_group, out_nov):  # pragma: no cover
    """Row ``t``'s calibrated group and fault probabilities from its classifier's ``p`` (its
    signature ``age`` seconds old), and its novelty."""
    temperature = row_temperature(params, age)
    posterior_row(p, params, temperature, gp, out_group[t], out_fault[t])
    out_nov[t] = novelty_score_row(row, params.novelty)
