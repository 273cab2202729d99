"""The healthy data a valve is commissioned on: checked before anything is fitted.

Commissioning learns the valve from data the user declares fault-free. `check_healthy` refuses
data that cannot identify the normal models, with a message naming the problem: too few
complete seconds, a channel that does not move (a stuck stem, a constant command: the models of
X and F would be fitted on one point), or labelled fault runs. `operating_range` reports what
the data cover, which is where the commissioned model can be trusted.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import xarray as xr

from bayes_fdi.datasets import CHANNELS, validate_dataset

__all__ = ["MIN_HEALTHY_SECONDS", "MIN_SPREAD", "check_healthy", "operating_range"]

#: Fewest complete seconds (every channel finite) commissioning needs.
MIN_HEALTHY_SECONDS = 900
#: Smallest standard deviation (full scale) of CV, X and F over the healthy data: about three
#: times the sensors' noise (0.0014); a channel that moves less carries no information.
MIN_SPREAD = 0.004


def _complete(runs: xr.Dataset) -> dict[str, np.ndarray]:
    data = {c: np.asarray(runs[c].transpose("run", "time").values, float).ravel() for c in CHANNELS}
    ok = np.ones(next(iter(data.values())).size, dtype=bool)
    for values in data.values():
        ok &= np.isfinite(values)
    return {c: v[ok] for c, v in data.items()}


def check_healthy(runs: xr.Dataset) -> xr.Dataset:
    """Return ``runs`` (dims ``run``, ``time``) if they can commission a valve, else raise a
    `ValueError` that names the problem."""
    if not isinstance(runs, xr.Dataset):
        raise ValueError(f"healthy data must be an xarray.Dataset, got {type(runs).__name__}")
    if "run" not in runs.dims:
        runs = runs.drop_vars([c for c in runs.coords if runs[c].ndim == 0]).expand_dims("run")
    validate_dataset(runs, require=CHANNELS, allow_nan=True)
    if "state" in runs.coords:
        bad = sorted(set(np.asarray(runs["state"].values).astype(str).ravel()) - {"fn"})
        if bad:
            raise ValueError(f"healthy data must be fault-free; runs are labelled {bad}")
    data = _complete(runs)
    n = data["X"].size
    if n < MIN_HEALTHY_SECONDS:
        raise ValueError(
            f"only {n} complete seconds of healthy data (every channel present); the normal models "
            f"need at least {MIN_HEALTHY_SECONDS} s, an hour or more is better"
        )
    for c in ("CV", "X", "F"):
        spread = float(np.std(data[c]))
        if spread < MIN_SPREAD:
            raise ValueError(
                f"{c} hardly moves in the healthy data (standard deviation {spread:.2g} of full "
                f"scale, below {MIN_SPREAD}): the normal models cannot be identified from it"
                + (" (a stuck stem or a frozen reading?)" if c == "X" else "")
            )
    return runs


def operating_range(runs: xr.Dataset) -> dict[str, Any]:
    """What the healthy data cover: per channel the 1st, 50th and 99th percentiles (full scale)
    and the complete seconds."""
    data = _complete(runs)
    return {
        "seconds": int(data["X"].size),
        **{
            c: {
                k: float(v)
                for k, v in zip(
                    ("p01", "p50", "p99"), np.percentile(data[c], [1, 50, 99]), strict=True
                )
            }
            for c in CHANNELS
        },
    }
