"""Posterior predictive check of a fitted twin on held-out healthy data.

:func:`predictive_check` simulates the held-out recording's gap-free stretches with posterior
draws (`bayes_fdi.twin.twin.ActuatorTwin.predict`) and reports, per channel X and F, the share
of recorded samples inside the central posterior predictive interval, the interval's mean
width, and the RMS error of the posterior predictive mean next to that of the nominal model.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import xarray as xr

from bayes_fdi.actuator import NOMINAL, simulate
from bayes_fdi.twin.simulator import OUTPUTS, cut_windows

if TYPE_CHECKING:  # the twin imports this module
    from bayes_fdi.twin.twin import ActuatorTwin

__all__ = ["TwinCheck", "predictive_check"]


class TwinCheck(NamedTuple):
    """Scores of the posterior predictive on held-out data, per channel (``"X"``, ``"F"``).

    ``coverage``: share of samples inside the central ``level`` interval; ``width``: the
    interval's mean width; ``rms``: RMS error of the posterior predictive mean (noise-free);
    ``rms_nominal``: RMS error of the nominal model; ``n_samples``: samples scored.
    """

    level: float
    coverage: dict[str, float]
    width: dict[str, float]
    rms: dict[str, float]
    rms_nominal: dict[str, float]
    n_samples: int


def predictive_check(
    twin: ActuatorTwin,
    heldout: xr.Dataset,
    *,
    n_draws: int = 200,
    seed: int = 0,
    level: float = 0.95,
) -> TwinCheck:
    """Coverage, interval width and RMS error of the twin's posterior predictive on ``heldout``.

    Every gap-free stretch of every run is simulated as a whole from its first sample; its first
    ``twin.settle`` s are not scored (as in the fit). ``seed`` selects the draws.
    """
    if not 0.0 < float(level) < 1.0:
        raise ValueError(f"level must lie in (0, 1), got {level!r}")
    length = int(heldout.sizes["time"])
    windows = cut_windows(heldout, window=max(length, 1), settle=int(twin.settle), max_seconds=None)
    pred = twin.predict(windows.inputs, n_draws=n_draws, seed=seed)
    nominal = simulate(
        windows.inputs, noise=False, parameters=NOMINAL, integrator=twin.integrator,
        hold=twin.hold, warmup=twin.warmup,
    )  # fmt: skip
    mask = windows.mask
    alpha = (1.0 - float(level)) / 2.0
    coverage, width, rms, rms_nominal = {}, {}, {}, {}
    for c, name in enumerate(OUTPUTS):
        observed = windows.observed[..., c]
        low, high = np.quantile(pred[name].values, [alpha, 1.0 - alpha], axis=0)
        inside = (observed >= low) & (observed <= high)
        coverage[name] = float(inside[mask].mean())
        width[name] = float((high - low)[mask].mean())
        mean = pred[f"{name}_model"].values.mean(axis=0)
        rms[name] = float(np.sqrt(np.mean((observed - mean)[mask] ** 2)))
        base = nominal[name].transpose("run", "time").values
        rms_nominal[name] = float(np.sqrt(np.mean((observed - base)[mask] ** 2)))
    return TwinCheck(float(level), coverage, width, rms, rms_nominal, int(mask.sum()))
