"""Residual features: a registry of named per-window statistics.

The paper classifies each run by two numbers, the mean of the position residual ``r1`` and
the mean of the flow residual ``r2`` over the run (``mean_r1``, ``mean_r2``; the defaults).
Other statistics are registered here and can be selected by name, and new ones are added
with `register_feature`::

    import numpy as np
    from bayes_fdi.diagnosis.isolation.features import register_feature

    @register_feature("p95_abs_r2")
    def p95_abs_r2(res):
        # res: residual dataset restricted to one window, dims (run, time)
        return np.nanpercentile(np.abs(res["r2"].values), 95, axis=1)

A feature function receives the residual dataset (as returned by
`bayes_fdi.diagnosis.normal_models.static.NormalModels.residuals`) restricted to one window, with
dims
``(run, time)``, and returns one value per run. NaN residuals (gaps in plant records) are
ignored by the built-in statistics (``nanmean`` etc.); a window with no finite residual gives
NaN, which the diagnoser reports as an error rather than guessing.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
import xarray as xr

__all__ = [
    "DEFAULT_FEATURES",
    "FEATURES",
    "extract_features",
    "register_feature",
    "window_bounds",
]

FeatureFunction = Callable[[xr.Dataset], np.ndarray]

#: The registry: feature name -> function of a residual dataset window, returning (n_runs,).
FEATURES: dict[str, FeatureFunction] = {}

#: The paper's two features (mean residuals over the run).
DEFAULT_FEATURES: tuple[str, ...] = ("mean_r1", "mean_r2")


def register_feature(
    name: str, func: FeatureFunction | None = None, *, overwrite: bool = False
) -> FeatureFunction | Callable[[FeatureFunction], FeatureFunction]:
    """Register a per-window feature function under ``name``.

    Usable as a decorator (``@register_feature("name")``) or directly
    (``register_feature("name", func)``).

    Parameters
    ----------
    name
        Feature name used in ``extract_features(names=...)``.
    func
        Function ``f(res) -> (n_runs,)`` of a residual dataset window with dims ``(run, time)``.
    overwrite
        Allow replacing an existing feature of the same name.

    Returns
    -------
    callable
        ``func`` itself (or the decorator).
    """
    if not isinstance(name, str) or not name:
        raise ValueError("feature name must be a non-empty string")

    def decorator(f: FeatureFunction) -> FeatureFunction:
        if not callable(f):
            raise ValueError(f"feature {name!r} must be callable")
        if name in FEATURES and not overwrite and FEATURES[name] is not f:
            raise ValueError(f"feature {name!r} is already registered (pass overwrite=True)")
        FEATURES[name] = f
        return f

    if func is None:
        return decorator
    return decorator(func)


def _values(res: xr.Dataset, var: str) -> np.ndarray:
    if var not in res.data_vars:
        raise ValueError(f"residual dataset lacks {var!r} (has {sorted(res.data_vars)})")
    return np.asarray(res[var].transpose("run", "time").values, dtype=np.float64)


def _nanstat(stat: Callable[..., np.ndarray], values: np.ndarray) -> np.ndarray:
    out = np.full(values.shape[0], np.nan)
    ok = np.isfinite(values).any(axis=1)
    if ok.any():
        out[ok] = stat(values[ok], axis=1)
    return out


def _make_builtin(stat_name: str, var: str) -> FeatureFunction:
    stats: dict[str, Callable[[np.ndarray], np.ndarray]] = {
        "mean": lambda v: _nanstat(np.nanmean, v),
        "std": lambda v: _nanstat(lambda a, axis: np.nanstd(a, axis=axis, ddof=0), v),
        "rms": lambda v: np.sqrt(_nanstat(np.nanmean, v**2)),
        "max_abs": lambda v: _nanstat(np.nanmax, np.abs(v)),
    }
    stat = stats[stat_name]

    def feature(res: xr.Dataset) -> np.ndarray:
        return stat(_values(res, var))

    feature.__name__ = f"{stat_name}_{var}"
    feature.__doc__ = f"{stat_name} of {var} over the window (NaN ignored)."
    return feature


for _stat in ("mean", "std", "rms", "max_abs"):
    for _var in ("r1", "r2", "z1", "z2"):
        register_feature(f"{_stat}_{_var}", _make_builtin(_stat, _var))
del _stat, _var


def window_bounds(n_times: int, window: int | None, step: int | None = None) -> np.ndarray:
    """Start and stop indices of the feature windows over ``n_times`` samples.

    Parameters
    ----------
    n_times
        Number of time samples in a run.
    window
        Window length in samples; ``None`` means one window over the whole run.
    step
        Hop between window starts (default: ``window``, non-overlapping). Windows that would
        run past the end are not formed (a trailing partial window is not used).

    Returns
    -------
    numpy.ndarray
        Integer array ``(n_windows, 2)`` of ``[start, stop)`` indices.
    """
    if n_times < 1:
        raise ValueError("runs have no time samples")
    if window is None:
        return np.array([[0, n_times]], dtype=np.int64)
    window = int(window)
    step = window if step is None else int(step)
    if window < 1 or step < 1:
        raise ValueError(f"window and step must be positive, got window={window}, step={step}")
    if window > n_times:
        raise ValueError(f"window ({window}) is longer than the runs ({n_times} samples)")
    starts = np.arange(0, n_times - window + 1, step, dtype=np.int64)
    return np.stack([starts, starts + window], axis=1)


def extract_features(
    res: xr.Dataset,
    names: Sequence[str] = DEFAULT_FEATURES,
    window: int | None = None,
    step: int | None = None,
) -> tuple[np.ndarray, tuple[str, ...]]:
    """Compute named features per run (or per window of each run).

    Parameters
    ----------
    res
        Residual dataset with dims ``(run, time)`` (``r1``, ``r2``, ``z1``, ``z2``, ...).
    names
        Registered feature names (see ``FEATURES``).
    window, step
        Window length and hop in samples (see `window_bounds`); ``None`` = whole run.

    Returns
    -------
    features : numpy.ndarray
        ``(n_runs, n_features)`` when ``window`` is None, else ``(n_runs, n_windows,
        n_features)``.
    names : tuple of str
        The feature names, in column order.
    """
    if isinstance(names, str):
        names = (names,)
    names = tuple(names)
    if not names:
        raise ValueError("at least one feature name is needed")
    unknown = [n for n in names if n not in FEATURES]
    if unknown:
        raise ValueError(f"unknown feature(s) {unknown}; registered: {sorted(FEATURES)}")
    if not isinstance(res, xr.Dataset) or "run" not in res.dims or "time" not in res.dims:
        raise ValueError("features need a residual dataset with dims ('run', 'time')")
    bounds = window_bounds(res.sizes["time"], window, step)
    n_runs = res.sizes["run"]
    out = np.empty((n_runs, len(bounds), len(names)))
    for w, (start, stop) in enumerate(bounds):
        part = res.isel(time=slice(int(start), int(stop)))
        for j, name in enumerate(names):
            col = np.asarray(FEATURES[name](part), dtype=np.float64)
            if col.shape != (n_runs,):
                raise ValueError(
                    f"feature {name!r} returned shape {col.shape}, expected ({n_runs},)"
                )
            out[:, w, j] = col
    if window is None:
        out = out[:, 0, :]
    return out, names
