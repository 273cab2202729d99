"""Residuals of the dynamic normal models: ``r = y - y_hat`` and ``z = r / std``, censored at the
sensors' rails (`standardised_residuals`), and the sensors' range and rail tolerance."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["RAIL_TOL", "SENSOR_RANGE", "standardised_residuals"]

#: Output range of the sensors (DABLib clips every measurement to [0, 1]).
SENSOR_RANGE = (0.0, 1.0)
#: A measurement or prediction this close to a rail of `SENSOR_RANGE` is "at the rail".
RAIL_TOL = 5e-3


def standardised_residuals(y: Any, y_hat: Any, std: Any) -> tuple[np.ndarray, np.ndarray]:
    """Residuals ``r = y - y_hat`` and ``z = r / std``, with ``z = 0`` where censored.

    A sample is censored when the measurement and the prediction sit at the same rail of
    `SENSOR_RANGE` (within `RAIL_TOL`): the clipped sensor cannot show a change there.
    NaN stays NaN.
    """
    y = np.asarray(y, dtype=np.float64)
    y_hat = np.asarray(y_hat, dtype=np.float64)
    r = y - y_hat
    with np.errstate(invalid="ignore", divide="ignore"):
        z = r / np.asarray(std, dtype=np.float64)
        lo, hi = SENSOR_RANGE
        censored = ((y >= hi - RAIL_TOL) & (y_hat >= hi - RAIL_TOL)) | (
            (y <= lo + RAIL_TOL) & (y_hat <= lo + RAIL_TOL)
        )
    z = np.where(censored & np.isfinite(z), 0.0, z)
    return r, z
