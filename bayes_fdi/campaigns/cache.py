"""The paper's campaigns as datasets: simulated once, cached as netCDF, split into train and test.

`load_or_simulate` simulates a campaign file (or loads it from the cache, keyed by the SHA-256
of the campaign file, of the simulator's source code, the seed and the ``small`` flag);
`split_train_test` takes the first ``n_train`` runs of every state for training (the paper: 20).
"""

from __future__ import annotations

import hashlib
import os
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from bayes_fdi.datasets import load_dataset, save_dataset, validate_dataset

__all__ = [
    "SMALL_DURATION",
    "SMALL_RUNS_PER_STATE",
    "campaign_file",
    "load_or_simulate",
    "split_train_test",
]

#: ``small=True``: runs per state (20 train + 4 test) ...
SMALL_RUNS_PER_STATE: int = 24

#: ... and seconds per run (the paper: 350).
SMALL_DURATION: int = 120


def campaign_file(name: str | os.PathLike) -> Path:
    """Locate a campaign TOML file.

    Parameters
    ----------
    name
        A path to a ``.toml`` file, or a shipped campaign name (``"paper-simulated"``,
        ``"paper-lublin"``) looked up in ``./sim/`` and then among the campaigns shipped with the
        package (`bayes_fdi.campaigns.shipped`).

    Returns
    -------
    pathlib.Path
    """
    path = Path(name)
    if path.suffix == ".toml":
        if not path.is_file():
            raise ValueError(f"campaign file {os.fspath(path)!r} does not exist")
        return path
    from bayes_fdi.campaigns.shipped import campaign_folder

    candidates = [
        Path.cwd() / "sim" / f"{name}.toml",
        campaign_folder() / f"{name}.toml",  # the shipped campaigns (checkout or installed)
    ]
    for c in candidates:
        if c.is_file():
            return c
    raise ValueError(
        f"campaign {os.fspath(name)!r} not found (looked in {', '.join(map(str, candidates))})"
    )


def _file_hash(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _simulator_hash() -> str:
    """SHA-256 over the simulator's source files (so a changed model never reuses a cache)."""
    from bayes_fdi import actuator
    from bayes_fdi.campaigns import parsing as campaign_parsing
    from bayes_fdi.campaigns import simulation as campaigns
    from bayes_fdi.campaigns import spec as campaign_spec

    files = [
        *sorted(Path(actuator.__file__).parent.glob("*.py")),
        Path(campaign_spec.__file__),
        Path(campaign_parsing.__file__),
        Path(campaigns.__file__),
    ]
    digest = hashlib.sha256()
    for f in files:
        digest.update(f.name.encode())
        digest.update(f.read_bytes())
    return digest.hexdigest()


def load_or_simulate(
    campaign: str | os.PathLike,
    *,
    seed: int = 0,
    cache_dir: str | os.PathLike | None = ".cache/datasets",
    small: bool = False,
    progress: bool = True,
) -> tuple[xr.Dataset, dict[str, Any]]:
    """Simulate a campaign, or load it from the netCDF cache.

    The cache file name holds the campaign name, the first 16 hex digits of the SHA-256 of the
    campaign file, 8 of the simulator's source code, the seed and ``small``; any change to the
    campaign file or to the actuator model makes a new entry.

    Parameters
    ----------
    campaign
        Campaign name or TOML path (see :func:`campaign_file`).
    seed
        Simulation seed.
    cache_dir
        Folder of cached datasets; ``None`` disables the cache.
    small
        Shrink the campaign (see :func:`_small_campaign`) for tests, notebooks and CI.
    progress
        Show the simulator's progress bar.

    Returns
    -------
    dataset : xarray.Dataset
    info : dict
        ``campaign`` (name), ``campaign_file``, ``campaign_sha256``, ``cache_file`` (or None),
        ``cached`` (bool), ``simulate_seconds`` (0 when cached).
    """
    from bayes_fdi.campaigns import simulation as campaigns

    path = campaign_file(campaign)
    digest = _file_hash(path)
    name = path.stem
    info: dict[str, Any] = {
        "campaign": name,
        "campaign_file": os.fspath(path),
        "campaign_sha256": digest,
        "cache_file": None,
        "cached": False,
        "simulate_seconds": 0.0,
    }
    cache_path = None
    if cache_dir is not None:
        suffix = "-small" if small else ""
        code = _simulator_hash()[:8]
        info["simulator_sha256_8"] = code
        cache_path = Path(cache_dir) / f"{name}-{digest[:16]}-{code}-seed{int(seed)}{suffix}.nc"
        info["cache_file"] = os.fspath(cache_path)
        if cache_path.is_file():
            ds = load_dataset(cache_path)
            info["cached"] = True
            return ds, info
    spec = campaigns.load_campaign(path)
    if small:
        spec = _small_campaign(spec)
    import torch

    # The simulator's parallel (numba/OpenMP) kernels raise torch's intra-op thread count for
    # the whole process; restore it so that the models fitted next compute exactly as they do
    # on a cached dataset (summation order depends on the thread count).
    n_threads = torch.get_num_threads()
    t0 = time.perf_counter()
    try:
        ds = campaigns.simulate_campaign(spec, seed=int(seed), progress=progress)
    finally:
        torch.set_num_threads(n_threads)
    info["simulate_seconds"] = time.perf_counter() - t0
    validate_dataset(ds, require=("CV", "P1", "P2", "T1", "X", "F"))
    if cache_path is not None:
        cache_path.parent.mkdir(parents=True, exist_ok=True)
        tmp = cache_path.with_suffix(".tmp.nc")
        save_dataset(ds, tmp)
        os.replace(tmp, cache_path)
    return ds, info


def _small_campaign(spec: Any) -> Any:
    """Small variant: :data:`SMALL_RUNS_PER_STATE` runs per state of :data:`SMALL_DURATION` s."""
    return spec.replace(
        runs_per_state=SMALL_RUNS_PER_STATE, duration=min(int(spec.duration), SMALL_DURATION)
    )


def split_train_test(
    ds: xr.Dataset, *, n_train: int, states: Sequence[str] | None = None
) -> tuple[xr.Dataset, xr.Dataset]:
    """Per state, the first ``n_train`` runs (in run order) train and the rest test.

    Parameters
    ----------
    ds
        Dataset with a ``state`` run coordinate.
    n_train
        Training runs per state.
    states
        States to keep (default: every state present). Each must have more than ``n_train``
        runs.

    Returns
    -------
    train, test : xarray.Dataset
        Subsets of ``ds`` (runs in their original order).
    """
    if "state" not in ds.coords:
        raise ValueError("dataset has no 'state' coordinate to split on")
    if n_train < 1:
        raise ValueError(f"n_train must be at least 1, got {n_train}")
    labels = np.asarray(ds["state"].values).astype(str)
    present = list(dict.fromkeys(labels))
    if states is None:
        states = present
    missing = [s for s in states if s not in present]
    if missing:
        raise ValueError(f"dataset has no runs of state(s) {missing} (has {present})")
    train_idx, test_idx = [], []
    for s in states:
        idx = np.flatnonzero(labels == s)
        if idx.size <= n_train:
            raise ValueError(
                f"state {s!r} has {idx.size} runs; need more than n_train={n_train} "
                "(the rest are the test runs)"
            )
        train_idx.append(idx[:n_train])
        test_idx.append(idx[n_train:])
    train = np.sort(np.concatenate(train_idx))
    test = np.sort(np.concatenate(test_idx))
    return ds.isel(run=train), ds.isel(run=test)
