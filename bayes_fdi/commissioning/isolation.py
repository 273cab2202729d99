"""The isolation of a commissioned diagnoser, fitted on the valve's transplanted fault libraries.

`fit_commissioned_isolation` gives a fitted `~bayes_fdi.diagnosis.OnlineDiagnoser` (its normal
models, whitening, detector and envelope fitted on the healthy data) its isolator, from three
transplanted libraries (`~bayes_fdi.diagnosis.online.training.fit_isolation`): the first trains
the classifier, the second finds the isolability groups, the third calibrates the group
probabilities. It differs from ``OnlineDiagnoser.fit`` with fault runs in one respect: the
groups come from the held-out confusion as the diagnoser names faults and as a benchmark
scores them, every detected faulty second of the second library (``group_rule="naming"``),
and a consistent one-way misnaming (fault ``a`` named ``b`` in a share of its seconds at least
the diagnoser's ``group_threshold``) merges the two, where the balanced pairwise rule of the
simulator-trained model halves it.
"""

from __future__ import annotations

import time
from typing import Any

from bayes_fdi.diagnosis.online.training import Runs, attach_isolation

__all__ = ["GROUP_RULE", "fit_commissioned_isolation"]

#: How a commissioned diagnoser's isolability groups are found
#: (`~bayes_fdi.diagnosis.isolation.isolator.FaultIsolator`'s ``group_rule``).
GROUP_RULE = "naming"


def fit_commissioned_isolation(
    diagnoser: Any, training: Runs, validation: Runs, calibration: Runs
) -> Any:
    """Fit the isolation of ``diagnoser`` (an `OnlineDiagnoser` fitted for detection only) on
    transplanted fault runs, in place; returns ``diagnoser``.

    Parameters
    ----------
    diagnoser
        Fitted on the healthy data without fault runs; its parameters (``calibrator``,
        ``isolation_classifier``, ``group_threshold``, ``detect_rate``,
        ``max_signatures_per_fault``, ``random_state``) set the isolation's; its
        ``group_rule`` is set to `GROUP_RULE`.
    training, validation, calibration
        The libraries that train the classifier, find the groups (`GROUP_RULE`) and
        calibrate the group probabilities.
    """
    if getattr(diagnoser, "isolator_", None) is not None:
        raise ValueError("the diagnoser already has an isolator: fit it without fault runs")
    t0 = time.perf_counter()
    seconds = dict(diagnoser.fit_seconds_)
    diagnoser.set_params(group_rule=GROUP_RULE)
    attach_isolation(diagnoser, training, validation, calibration, seconds=seconds)
    seconds["total"] = seconds.get("total", 0.0) + time.perf_counter() - t0
    diagnoser.fit_seconds_ = seconds
    return diagnoser.reset()
