"""The dataset format: labelled actuator runs as an :class:`xarray.Dataset`.

One dataset type is used throughout the project:

- dims ``run`` and ``time`` (seconds, 1 Hz; the ``time`` coordinate holds seconds);
- data variables ``CV``, ``P1``, ``P2``, ``T1``, ``X``, ``F`` of shape ``(run, time)``,
  normalised as DABLib does (P/4 MPa, T1/200 °C, X in [0, 1] of closing, F/40 t/h);
- per-run coordinates ``state`` (``"fn"`` or ``"f1"`` .. ``"f19"``), ``strength`` (signed, as the
  benchmark's fault vector), ``onset`` (s), ``profile`` (``"abrupt"`` or ``"incipient"``) and
  ``ramp`` (s, duration of an incipient ramp to full strength; 0 for abrupt);
- attributes ``campaign``, ``seed`` and ``bayes_fdi_version``.

Datasets are saved and loaded as netCDF (``.nc``); saving is atomic (a temporary file in the
destination's folder renamed over it, see `bayes_fdi.atomic`), so an interrupted or failed save
never leaves a partial file; a save that fills the disk says so (``OSError`` with
``errno.ENOSPC``, where netCDF itself only reports "HDF error"). `make_dataset` copies the arrays
it is given: the dataset never shares memory with the caller's arrays.
"""

from __future__ import annotations

import contextlib
import errno
import os
from collections.abc import Iterable, Sequence

import numpy as np
import xarray as xr

from bayes_fdi.atomic import atomic_path, check_output_path
from bayes_fdi.memory import format_bytes

__all__ = [
    "CHANNELS",
    "INPUT_CHANNELS",
    "MEASUREMENT_FAULTS",
    "OUTPUT_CHANNELS",
    "STATES",
    "load_dataset",
    "make_dataset",
    "save_dataset",
    "state_order",
    "validate_dataset",
]

INPUT_CHANNELS: tuple[str, ...] = ("CV", "P1", "P2", "T1")
OUTPUT_CHANNELS: tuple[str, ...] = ("X", "F")
CHANNELS: tuple[str, ...] = INPUT_CHANNELS + OUTPUT_CHANNELS
STATES: tuple[str, ...] = ("fn", *(f"f{i}" for i in range(1, 20)))
#: Faults of one measurement alone, beside the DAMADICS faults: the reading of X, F, P1 or P2
#: offset by a bias (profile "abrupt") or a drift (profile "incipient"); made by
#: `bayes_fdi.twin.transplant` (DAMADICS's own sensor faults are f13, in the positioner's loop,
#: and f19, a gain of the flow reading).
MEASUREMENT_FAULTS: tuple[str, ...] = ("bias_X", "bias_F", "bias_P1", "bias_P2")
PROFILES: tuple[str, ...] = ("abrupt", "incipient")
RUN_COORDS: tuple[str, ...] = ("state", "strength", "onset", "profile", "ramp")
#: File-name endings :func:`save_dataset` accepts (netCDF).
NETCDF_SUFFIXES: tuple[str, ...] = (".nc", ".nc4")


def _version() -> str:
    from bayes_fdi import __version__

    return __version__


def make_dataset(
    channels: dict[str, np.ndarray],
    *,
    state: Sequence[str] | str = "fn",
    strength: Sequence[float] | float = 0.0,
    onset: Sequence[float] | float = 0.0,
    profile: Sequence[str] | str = "abrupt",
    ramp: Sequence[float] | float = 0.0,
    campaign: str = "",
    seed: int | None = None,
    attrs: dict | None = None,
    allow_nan: bool = False,
) -> xr.Dataset:
    """Build a dataset in the project's format from ``(run, time)`` arrays.

    Parameters
    ----------
    channels
        Mapping of channel name (a subset of ``CHANNELS``) to arrays of shape
        ``(n_runs, n_times)``, or ``(n_times,)`` for a single run.
    state, strength, onset, profile, ramp
        Per-run labels; a scalar applies to every run.
    campaign, seed, attrs
        Stored as dataset attributes (with the package version).
    allow_nan
        Whether NaN gaps are allowed in the channels (as in :func:`validate_dataset`).

    Returns
    -------
    xarray.Dataset
        A validated dataset.
    """
    if not channels:
        raise ValueError("make_dataset needs at least one channel")
    unknown = set(channels) - set(CHANNELS)
    if unknown:
        raise ValueError(f"unknown channel(s) {sorted(unknown)}; known channels are {CHANNELS}")
    arrays = {}
    for name, values in channels.items():
        arr = _channel_array(name, values)
        if arr.ndim == 1:
            arr = arr[None, :]
        if arr.ndim != 2:
            raise ValueError(f"channel {name!r} must be 1-D or 2-D (run, time), got {arr.shape}")
        arrays[name] = arr
    shapes = {a.shape for a in arrays.values()}
    if len(shapes) != 1:
        found = {k: v.shape for k, v in arrays.items()}
        raise ValueError(f"channels have different shapes: {found}")
    n_runs, n_times = shapes.pop()

    def per_run(value, name, dtype):
        if dtype is np.float64:
            value = _label_numbers(value, name)
        elif not isinstance(value, str) and np.ndim(value) > 0:
            value = [_label_text(v, name) for v in np.asarray(value, dtype=object).ravel()]
        else:
            value = _label_text(value, name)
        if isinstance(value, str) or np.ndim(value) == 0:
            return np.full(n_runs, value, dtype=dtype)
        out = np.array(value, dtype=dtype)
        if out.shape != (n_runs,):
            raise ValueError(
                f"{name} must be a scalar or have one entry per run ({n_runs}), "
                f"got shape {np.shape(value)}"
            )
        return out

    coords = {
        "run": np.arange(n_runs),
        "time": np.arange(n_times, dtype=np.float64),
        "state": ("run", per_run(state, "state", object).astype(str)),
        "strength": ("run", per_run(strength, "strength", np.float64)),
        "onset": ("run", per_run(onset, "onset", np.float64)),
        "profile": ("run", per_run(profile, "profile", object).astype(str)),
        "ramp": ("run", per_run(ramp, "ramp", np.float64)),
    }
    ds = xr.Dataset(
        {name: (("run", "time"), arr) for name, arr in arrays.items()},
        coords=coords,
        attrs={
            "campaign": campaign,
            "seed": -1 if seed is None else int(seed),
            "bayes_fdi_version": _version(),
            **(attrs or {}),
        },
    )
    validate_dataset(ds, require=(), allow_nan=allow_nan)
    late = np.flatnonzero((ds["state"].values != "fn") & (ds["onset"].values >= n_times))
    if late.size:
        r = int(late[0])
        raise ValueError(
            f"run {r}: fault onset {float(ds['onset'].values[r]):g} s is at or after the run's "
            f"end ({n_times} samples of 1 s); the fault would be labelled but never present"
        )
    return ds


def _channel_array(name: str, values) -> np.ndarray:
    """A float64 copy of a channel's values; complex, text and boolean data are refused."""
    raw = np.asarray(values)
    if np.iscomplexobj(raw):
        raise ValueError(
            f"channel {name!r} is complex; channels are real (pass .real or abs() explicitly)"
        )
    if raw.dtype.kind not in "iuf":
        if raw.dtype.kind == "O":
            try:
                return _channel_array(name, np.array(raw.tolist(), dtype=np.float64))
            except (TypeError, ValueError):
                pass
        raise ValueError(f"channel {name!r} must hold numbers, got dtype {raw.dtype}")
    return np.array(raw, dtype=np.float64, copy=True)


def _label_numbers(value, name: str):
    try:
        out = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be numbers, got {value!r}") from None
    if np.iscomplexobj(np.asarray(value)):
        raise ValueError(f"{name} must be real numbers, got {value!r}")
    if not np.all(np.isfinite(out)):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if name in ("onset", "ramp") and np.any(out < 0):
        raise ValueError(f"{name} must be >= 0 s, got {value!r}")
    return out if out.ndim else float(out)


def _label_text(value, name: str) -> str:
    if not isinstance(value, str | np.str_):
        raise ValueError(f"{name} must be text (e.g. 'fn', 'f1'), got {value!r}")
    return str(value)


def validate_dataset(
    ds: xr.Dataset, require: Iterable[str] = INPUT_CHANNELS, *, allow_nan: bool = False
) -> xr.Dataset:
    """Check that ``ds`` is in the project's format; raise ``ValueError`` naming the problem.

    Parameters
    ----------
    ds
        The dataset to check.
    require
        Channels that must be present.
    allow_nan
        Whether NaN gaps are allowed in the channels (real plant records have them).

    Returns
    -------
    xarray.Dataset
        ``ds`` itself, unchanged.
    """
    if not isinstance(ds, xr.Dataset):
        raise ValueError(f"expected an xarray.Dataset, got {type(ds).__name__}")
    for dim in ("run", "time"):
        if dim not in ds.dims:
            raise ValueError(f"dataset has no {dim!r} dimension (dims are {tuple(ds.dims)})")
    missing = [c for c in require if c not in ds.data_vars]
    if missing:
        raise ValueError(f"dataset lacks channel(s) {missing}")
    unknown = [v for v in ds.data_vars if v not in CHANNELS]
    if unknown:
        raise ValueError(f"unknown channel(s) {unknown}; known channels are {CHANNELS}")
    for name in ds.data_vars:
        if ds[name].dims != ("run", "time"):
            raise ValueError(f"channel {name!r} has dims {ds[name].dims}, expected ('run', 'time')")
        values = ds[name].values
        if not np.issubdtype(values.dtype, np.number):
            raise ValueError(f"channel {name!r} is not numeric (dtype {values.dtype})")
        if np.iscomplexobj(values):
            raise ValueError(f"channel {name!r} is complex; channels are real")
        if np.isinf(values).any():
            raise ValueError(f"channel {name!r} contains inf")
        if not allow_nan and np.isnan(values).any():
            raise ValueError(
                f"channel {name!r} contains {int(np.isnan(values).sum())} NaN value(s)"
            )
    for name in ("strength", "onset", "ramp"):
        if name in ds.coords:
            values = ds[name].values
            if not np.issubdtype(values.dtype, np.number) or np.iscomplexobj(values):
                raise ValueError(f"coordinate {name!r} must be real numbers (dtype {values.dtype})")
            if not np.all(np.isfinite(values)):
                raise ValueError(f"coordinate {name!r} contains NaN or inf")
    if "state" in ds.coords:
        bad = sorted(set(map(str, ds["state"].values)) - set(STATES) - set(MEASUREMENT_FAULTS))
        if bad:
            raise ValueError(
                f"unknown state label(s) {bad}; states are fn, f1..f19, "
                + ", ".join(MEASUREMENT_FAULTS)
            )
    if "profile" in ds.coords:
        bad = sorted(set(map(str, ds["profile"].values)) - set(PROFILES))
        if bad:
            raise ValueError(f"unknown profile(s) {bad}; profiles are {PROFILES}")
    return ds


def save_dataset(ds: xr.Dataset, path: str | os.PathLike) -> None:
    """Save a dataset to netCDF atomically; :func:`load_dataset` reads it back exactly.

    The dataset is written to a temporary file in the destination's folder, flushed to disk and
    renamed over ``path``: the file appears whole or not at all. Ctrl-C (``SIGINT``) or
    ``SIGTERM`` during the write let it finish, remove the temporary file and are then re-raised.

    Raises
    ------
    ValueError
        If ``ds`` is not a valid dataset, or ``path`` does not end in ``.nc`` / ``.nc4``, is a
        folder, or its folder does not exist or is not writable (checked before writing).
    OSError
        If the write fails; ``errno.ENOSPC`` ("No space left on device", with the space free)
        where the disk filled up. Nothing is left at ``path`` nor beside it.
    """
    validate_dataset(ds, require=(), allow_nan=True)
    check_output_path(path, suffixes=NETCDF_SUFFIXES, what="dataset file")
    encoding = {name: {"zlib": True, "complevel": 4} for name in ds.data_vars}
    with atomic_path(path) as tmp:
        try:
            ds.to_netcdf(tmp, engine="netcdf4", encoding=encoding)
        except (RuntimeError, OSError) as exc:
            full = _disk_full(exc, ds, tmp, os.fspath(path))
            # HDF5 keeps a failed file open: emptied, it gives its blocks back at once
            # (removed by atomic_path, it would hold them until the process ends)
            with contextlib.suppress(OSError):
                os.truncate(tmp, 0)
            if full is not None:
                raise full from exc
            raise


def _disk_full(exc: BaseException, ds: xr.Dataset, tmp: str, path: str) -> OSError | None:
    """``OSError(ENOSPC)`` where a failed write left less free space than a variable needs.

    netCDF reports a full disk as "NetCDF: HDF error"; the free space, read while the partial
    temporary file still holds its blocks, tells.
    """
    if isinstance(exc, OSError) and exc.errno == errno.ENOSPC:
        return None  # already says so
    try:
        stats = os.statvfs(os.path.dirname(os.path.abspath(tmp)))
    except (OSError, AttributeError):  # no statvfs (Windows)
        return None
    root = getattr(os, "geteuid", lambda: -1)() == 0  # root may use the reserved blocks
    blocks = stats.f_bfree if root else stats.f_bavail
    free = blocks * stats.f_frsize
    largest = max((ds[name].nbytes for name in ds.data_vars), default=0)
    if free >= max(largest, 1 << 20):
        return None
    return OSError(
        errno.ENOSPC,
        f"No space left on device: {format_bytes(free)} free after writing part of the "
        f"dataset ({format_bytes(ds.nbytes)} uncompressed; netCDF said: {exc}); nothing "
        "was written",
        path,
    )


def load_dataset(path: str | os.PathLike) -> xr.Dataset:
    """Load a dataset saved by :func:`save_dataset` (fully into memory) and validate it.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    IsADirectoryError
        If ``path`` is a folder.
    ValueError
        If the file is not a readable netCDF dataset in the project's format.
    """
    text = os.fspath(path)
    if not os.path.exists(text):
        raise FileNotFoundError(2, "dataset file does not exist", text)
    if os.path.isdir(text):
        raise IsADirectoryError(21, "dataset path is a folder, not a file", text)
    try:
        with xr.open_dataset(path, engine="netcdf4") as opened:
            ds = opened.load()
    except FileNotFoundError:
        raise
    except Exception as exc:  # netCDF4 raises OSError / RuntimeError variants
        raise ValueError(f"cannot read dataset {os.fspath(path)!r}: {exc}") from exc
    for name in ("state", "profile"):
        if name in ds.coords:
            ds = ds.assign_coords({name: ("run", ds[name].values.astype(str))})
    return validate_dataset(ds, require=(), allow_nan=True)


def state_order(state: str) -> tuple[int, int, str]:
    """Sort key of state labels: ``fn``, then ``f1`` .. ``f19`` by number, then the measurement
    faults in the order of `MEASUREMENT_FAULTS`, then any other label alphabetically."""
    if state == "fn":
        return (0, 0, state)
    if state in STATES:
        return (1, int(state[1:]), state)
    if state in MEASUREMENT_FAULTS:
        return (2, MEASUREMENT_FAULTS.index(state), state)
    return (3, 0, state)
