"""The training campaigns of the online diagnoser and `fit_online_diagnoser`.

The online diagnoser (`bayes_fdi.diagnosis.OnlineDiagnoser`) is fitted on simulated campaigns
declared in ``sim/``:

- ``online-normal.toml``: fault-free runs (normal models, whitening, detector threshold);
- ``online-faults-abrupt.toml`` and ``online-faults-incipient.toml``: every fault at
  magnitudes from 0.1 to 1.0, abrupt and ramping, each simulated with three seeds for the
  training, validation (isolability groups) and calibration (group probabilities) sets.

Every seed is below 1000, apart from the benchmark's evaluation seeds (>= 10 000, see
``bayes_fdi.benchmark.scenarios``). The group probabilities are recalibrated with a
`~bayes_fdi.calibration.TemperatureScaler`.

``small=True`` is a quick version for tests, notebooks and ``make demo``: fewer and shorter
runs, and lighter normal-model fits.
"""

from __future__ import annotations

import time
from typing import Any

import xarray as xr

from bayes_fdi.campaigns.parsing import load_campaign
from bayes_fdi.campaigns.simulation import simulate_campaign
from bayes_fdi.campaigns.spec import Campaign

__all__ = [
    "CAMPAIGNS",
    "SEED_OFFSETS",
    "fit_online_diagnoser",
    "online_campaigns",
    "simulate_online_campaigns",
]

#: The campaign files (names in ``sim/``).
CAMPAIGNS: dict[str, str] = {
    "normal": "online-normal",
    "abrupt": "online-faults-abrupt",
    "incipient": "online-faults-incipient",
}
#: Campaign seed of each set (plus the ``seed`` argument): all below 1000.
SEED_OFFSETS: dict[str, dict[str, int]] = {
    "normal": {"normal": 101},
    "abrupt": {"train": 201, "validation": 301, "calibration": 401},
    "incipient": {"train": 251, "validation": 351, "calibration": 451},
}
#: Overrides of the quick version (``small=True``).
SMALL: dict[str, dict[str, Any]] = {
    "normal": {"runs_per_state": 8, "duration": 600},
    "abrupt": {"runs_per_state": 3, "duration": 400, "faults.onset": 100.0},
    "incipient": {"runs_per_state": 1, "duration": 600, "faults.onset": 100.0,
                  "faults.ramp": 300.0},
}  # fmt: skip
#: Largest ``seed``: keeps every campaign seed below 1000.
MAX_SEED = 1000 - max(v for d in SEED_OFFSETS.values() for v in d.values())


def online_campaigns(*, small: bool = False) -> dict[str, Campaign]:
    """The three campaigns (``small``: the quick version)."""
    from bayes_fdi.campaigns.cache import campaign_file

    out = {}
    for key, name in CAMPAIGNS.items():
        overrides = SMALL[key] if small else {}
        out[key] = load_campaign(campaign_file(name), **overrides)
    return out


def simulate_online_campaigns(
    *, seed: int = 0, small: bool = False, progress: bool = True
) -> dict[str, list[xr.Dataset]]:
    """Simulate the training data: ``{"normal": [...], "train": [...], "validation": [...],
    "calibration": [...]}`` (lists of datasets, one per campaign)."""
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed < MAX_SEED:
        raise ValueError(f"seed must be an integer in [0, {MAX_SEED}), got {seed!r}")
    campaigns = online_campaigns(small=small)
    out: dict[str, list[xr.Dataset]] = {"normal": [], "train": [], "validation": [],
                                        "calibration": []}  # fmt: skip
    for key, campaign in campaigns.items():
        for part, offset in SEED_OFFSETS[key].items():
            ds = simulate_campaign(campaign, seed=offset + seed, progress=progress)
            out[part].append(ds)
    return out


def fit_online_diagnoser(
    *, seed: int = 0, small: bool = False, progress: bool = True, **params: Any
) -> Any:
    """Simulate the online training campaigns and fit an `OnlineDiagnoser` on them.

    Parameters
    ----------
    seed
        Added to every campaign seed (all stay below 1000).
    small
        The quick version (tests, notebooks, ``make demo``).
    progress
        Progress bars and a one-line summary on stderr.
    **params
        Parameters of `OnlineDiagnoser` (default: ``calibrator=TemperatureScaler()``,
        ``random_state=seed``; with ``small``, lighter normal models).

    Returns
    -------
    OnlineDiagnoser
        Fitted; ``fit_seconds_["simulation"]`` holds the simulation time.
    """
    import sys

    from bayes_fdi.calibration import TemperatureScaler
    from bayes_fdi.diagnosis import OnlineDiagnoser
    from bayes_fdi.diagnosis.normal_models.dynamic import DynamicNormalModels

    t0 = time.perf_counter()
    data = simulate_online_campaigns(seed=seed, small=small, progress=progress)
    simulated = time.perf_counter() - t0
    params.setdefault("calibrator", TemperatureScaler())
    params.setdefault("random_state", seed)
    if small:
        params.setdefault("max_signatures_per_fault", 25)
        params.setdefault(
            "normal_models",
            DynamicNormalModels(max_train_samples=800, calibration_folds=3, random_state=seed),
        )
    diag = OnlineDiagnoser(**params).fit(
        data["normal"][0] if len(data["normal"]) == 1 else xr.concat(data["normal"], "run"),
        data["train"],
        validation_runs=data["validation"],
        calibration_runs=data["calibration"],
    )
    diag.fit_seconds_["simulation"] = simulated
    if progress:
        s = diag.fit_seconds_
        print(
            f"online diagnoser fitted: simulation {simulated:.0f} s, normal models "
            f"{s['normal_models']:.0f} s, isolation {s.get('isolation', 0.0):.0f} s; "
            f"threshold {diag.threshold_:.2f}, {len(diag.groups_)} groups, undetectable "
            f"{', '.join(diag.undetectable_) or 'none'}",
            file=sys.stderr,
        )
    return diag
