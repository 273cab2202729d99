"""Checks of an online diagnoser's settings and of its fitted values.

`check_settings` refuses settings out of range before a fit; `check_fitted_values` refuses a
fitted diagnoser whose values cannot be right (a threshold that is NaN or not positive, a
clear level above it, bounds that are not finite), so that a damaged or tampered model file
fails when it is loaded, naming the value, rather than when it diagnoses.
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Any

import numpy as np

from bayes_fdi.diagnosis.isolation.isolator import GROUP_RULES

__all__ = ["NUMERIC_SETTINGS", "SETTING_RANGES", "check_fitted_values", "check_settings"]


#: Each numeric setting of an `OnlineDiagnoser` and the range `check_settings` requires of it.
SETTING_RANGES: Mapping[str, Callable[[Any], bool]] = MappingProxyType(
    {
        "false_alarm_hours": lambda v: v > 0,
        "cusum_k": lambda v: v >= 0,
        "glr_window": lambda v: isinstance(v, int) and v >= 1,
        "p_fault": lambda v: 0 <= v <= 1,
        "novelty_ratio": lambda v: v > 0,
        "coverage": lambda v: 0 < v < 1,
        "detect_rate": lambda v: 0 <= v <= 1,
        "input_margin": lambda v: v >= 0,
        "max_signatures_per_fault": lambda v: v >= 2,
        "fit_proof_seconds": lambda v: isinstance(v, int | np.integer) and v >= 0,
    }
)
#: The numeric settings `check_settings` checks, each of which must be a real number.
NUMERIC_SETTINGS: tuple[str, ...] = tuple(SETTING_RANGES)


def check_settings(params: Mapping[str, Any]) -> None:
    """Refuse settings that are not real numbers (a bool, a string) or out of range
    (`SETTING_RANGES`; ``params``: ``get_params()`` of an `OnlineDiagnoser`), and a
    ``group_rule`` not in `~bayes_fdi.diagnosis.isolation.isolator.GROUP_RULES`; the error
    names the setting."""
    for name in NUMERIC_SETTINGS:
        value = params[name]
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise ValueError(f"{name} must be a real number, got {value!r}")
    for name, in_range in SETTING_RANGES.items():
        if not in_range(params[name]):
            raise ValueError(f"{name} is out of range: {params[name]!r}")
    if params["group_rule"] not in GROUP_RULES:
        raise ValueError(
            f"group_rule must be one of {', '.join(GROUP_RULES)}, got {params['group_rule']!r}"
        )


def _finite(value: Any) -> bool:
    try:
        return bool(np.all(np.isfinite(np.asarray(value, dtype=np.float64))))
    except (TypeError, ValueError):
        return False


def check_fitted_values(values: Mapping[str, Any]) -> None:
    """Refuse fitted values that cannot be right (``vars()`` of a fitted `OnlineDiagnoser`)."""
    threshold = values.get("threshold_")
    if not (isinstance(threshold, (int, float)) and math.isfinite(threshold) and threshold > 0):
        raise ValueError(f"the detection threshold threshold_ must be finite and > 0: {threshold}")
    detector_threshold = getattr(values.get("detector_"), "threshold", threshold)
    if not (_finite(detector_threshold) and np.all(np.asarray(detector_threshold) > 0)):
        raise ValueError(f"the detector's threshold must be finite and > 0: {detector_threshold!r}")
    clear = values.get("clear_level_")
    if not (isinstance(clear, (int, float)) and math.isfinite(clear) and 0 <= clear < threshold):
        raise ValueError(
            f"the clear level clear_level_ must be finite, >= 0 and below the threshold "
            f"{threshold!r}: {clear!r}"
        )
    envelope = values.get("envelope_")
    low, high = getattr(envelope, "low_", None), getattr(envelope, "high_", None)
    if low is not None and not (_finite(low) and _finite(high) and np.all(low < high)):
        raise ValueError(f"the input envelope's bounds must be finite and ordered: {low}, {high}")
    for channel, known in (values.get("training_ranges_") or {}).items():
        if len(known) != 3 or not (known[0] <= known[1] <= known[2]):
            raise ValueError(f"training_ranges_[{channel!r}] must be 3 ordered values: {known!r}")
