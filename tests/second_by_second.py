"""An online component's ``update`` fed one second at a time (for tests that compare it with
``run`` over the whole recording)."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np


def second_by_second(component: Any, channels: Mapping[str, np.ndarray]) -> tuple[np.ndarray, Any]:
    """The rows ``component.update`` gives for each second of ``channels`` (equal-length
    ``(n,)`` arrays by name) from a fresh state, stacked, and the state after the last."""
    n = len(next(iter(channels.values())))
    state, rows = component.init_state(), []
    for t in range(n):
        row, state = component.update({c: v[t] for c, v in channels.items()}, state)
        rows.append(row)
    return np.vstack(rows), state
