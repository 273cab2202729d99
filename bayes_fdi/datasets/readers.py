"""Readers of actuator recordings: CSV, MATLAB ``.mat``, netCDF and the benchmark's day files.

Every reader returns an *unlabelled* one-run dataset in the project's format: dims ``run`` (one)
and ``time`` (seconds, 1 Hz), channels ``CV, P1, P2, T1, X, F`` normalised as DABLib does. An
unlabelled recording has no ``state`` coordinate (nor ``strength``, ``onset``, ``profile``,
``ramp``): nobody knows its state, and the format's ``"fn"`` would claim it is fault-free.

Units (``units=``): ``"normalised"`` (the default: the values already are), ``"physical"``
(:data:`PHYSICAL_UNITS`: CV and X in %, P1 and P2 in kPa, T1 in degC, F in t/h) or a mapping
giving the unit of every channel, e.g. ``{"CV": "%", "X": "%", "P1": "MPa", "P2": "MPa",
"T1": "K", "F": "kg/s"}`` (known units: :data:`UNITS`). The normalisation is DABLib's:
``P' = P / 4 MPa``, ``T1' = T1 / 200 degC``, ``F' = F / 40 t/h``, ``CV' = CV / 100 %``,
``X' = X / 100 %``. Nothing is clipped: a value outside the nominal range stays outside ``[0, 1]``.
Values implausible by orders of magnitude in their declared units are refused, naming the likely
units (`bayes_fdi.datasets.units.check_plausible_units`; ``check_units=False`` reads them as they
are): the default ``"normalised"`` has no silent effect on physical-looking data.

Sampling: the model runs at 1 Hz. A recording at another rate is an error unless the caller asks
for resampling (``resample="mean"``: the mean of the samples in each second, for faster
recordings, second ``k`` averaging the samples with ``k - 0.5 <= t < k + 0.5`` so that every sample
counts once; ``resample="linear"``: linear interpolation onto whole seconds between samples at
most two sampling steps apart, for slower ones). A second whose samples include a NaN, or that
no sample covers, is NaN. Missing timestamps at 1 Hz become NaN rows: gaps stay gaps (listed in
the ``gaps`` attribute, warned with :class:`RecordingGapWarning`; the diagnosis marks those
seconds BLIND). Nothing is filled or dropped; columns a reader does not use are listed in the
``ignored_columns`` attribute. A span that one jump makes over ten times what the samples cover
(a mistyped timestamp) is refused, naming the sample, and a 1-s grid beyond the memory available
too, before it is allocated (`bayes_fdi.datasets.time_grid`).

Formats
-------
CSV (:func:`read_csv`)
    A header row naming the columns ``time, CV, P1, P2, T1, X, F`` (any order, other columns
    allowed), or a ``columns`` mapping from the file's names to the channels. ``time`` holds
    seconds (or ISO date-times, converted to seconds from the first row; the first is kept in
    the ``time_origin`` attribute; with UTC offsets they are instants in UTC, the offsets met
    in ``time_offsets``); without a time column give ``rate`` (Hz). Empty cells and ``NaN``
    are gaps; any other non-number is an error naming its line and column. Read in chunks;
    duplicate names, trailing delimiters and shifted columns: `bayes_fdi.datasets.csv_columns`.
MATLAB (:func:`read_mat`)
    One vector variable per channel (and ``time``), named as the channels or through
    ``columns``. v4/v5/v7 files are read with scipy, v7.3 (HDF5) files with h5py.
netCDF (:func:`read_netcdf`)
    Variables named as the channels (or through ``columns``) along a ``time`` dimension whose
    coordinate holds seconds or date-times; a dataset already in the project's format (dims
    ``run``, ``time``) is accepted as is. ``chunks`` keeps it lazy (dask), for recordings that
    do not fit in memory. A variable's ``units`` attribute must agree with ``units=``.
Day files (:func:`read_day_file`)
    ``DDMM2001.txt`` of the Lublin benchmark, via `bayes_fdi.datasets.lublin.load_lublin_day`
    (its own per-actuator ranges; ``units`` does not apply). Such a recording keeps its
    ``day``/``actuator`` attributes and the real fault events of that day.

:func:`read_recording` picks the reader from the file name (``.csv``/``.tsv``, ``.mat``,
``.nc``/``.nc4``/``.cdf``/``.h5``, ``.txt`` = day file).
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import warnings
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
import xarray as xr

from bayes_fdi.datasets.csv_columns import read_csv_columns
from bayes_fdi.datasets.format import CHANNELS, validate_dataset
from bayes_fdi.datasets.time_grid import (
    RESAMPLE_METHODS,
    TIME_TOLERANCE,
    RecordingGapWarning,
    gap_summary,
    to_second_grid,
    to_seconds,
    warn_gaps,
)
from bayes_fdi.datasets.units import (
    PHYSICAL_UNITS,
    UNIT_ALIASES,
    UNITS,
    check_plausible_units,
    normalise,
    parse_units,
    to_physical,
    units_attribute,
)

__all__ = [
    "FORMATS",
    "PHYSICAL_UNITS",
    "RESAMPLE_METHODS",
    "UNITS",
    "RecordingGapWarning",
    "normalise",
    "parse_units",
    "read_csv",
    "read_day_file",
    "read_mat",
    "read_netcdf",
    "read_recording",
    "to_physical",
]

FORMATS: dict[str, str] = {
    ".csv": "csv",
    ".tsv": "csv",
    ".mat": "mat",
    ".nc": "netcdf",
    ".nc4": "netcdf",
    ".cdf": "netcdf",
    ".h5": "netcdf",
    ".txt": "day",
}


# ----------------------------------------------------------------------------------------------
# a file's columns to a one-run dataset
# ----------------------------------------------------------------------------------------------
def _build(
    time: np.ndarray,
    raw: dict[str, np.ndarray],
    units: str | Mapping[str, str],
    resample: str | None,
    source: str,
    fmt: str,
    attrs: Mapping[str, Any] | None = None,
    check_units: bool = True,
    label: Callable[[int], str] | None = None,
) -> xr.Dataset:
    """Normalise, put on the 1-s grid, and wrap into an unlabelled one-run dataset."""
    unit_of = parse_units(units)
    name_of = label or (lambda i: f"sample {i + 1}")
    for name, values in raw.items():
        if np.isinf(values).any():
            row = int(np.flatnonzero(np.isinf(values))[0])
            raise ValueError(f"{source}: {name} of {name_of(row)} is infinite")
    # the raw values are let go one by one (the readers hand over their arrays)
    normalised = {name: normalise(raw.pop(name), name, unit_of[name]) for name in CHANNELS}
    if check_units:
        check_plausible_units(xr.Dataset({c: ("time", v) for c, v in normalised.items()}),
                              unit_of, source)  # fmt: skip
    grid, channels, info = to_second_grid(time, normalised, resample, source, label, copy=False)
    gaps = gap_summary(grid, channels)
    ds = xr.Dataset(
        {name: (("run", "time"), channels[name][None, :]) for name in CHANNELS},
        coords={"run": [0], "time": grid},
        attrs={
            "source": source,
            "format": fmt,
            "units": units_attribute(unit_of),
            "sampling_step": info["sampling_step"],
            "resampled": info["resampled"],
            "gaps": json.dumps(gaps),
            **(attrs or {}),
        },
    )
    validate_dataset(ds, require=CHANNELS, allow_nan=True)
    warn_gaps(gaps, info.get("missing_seconds", 0), source)
    return ds


def _pick_columns(
    available: list[str], columns: Mapping[str, str] | None, source: str, rate: float | None
) -> tuple[dict[str, str], list[str]]:
    """channel -> source column, and the source columns left unused."""
    mapping = {str(k): str(v) for k, v in (columns or {}).items()}
    bad = sorted(set(mapping.values()) - {*CHANNELS, "time"})
    if bad:
        raise ValueError(
            f"columns maps to unknown channel(s) {bad}; use time, {', '.join(CHANNELS)}"
        )
    absent = sorted(set(mapping) - set(available))
    if absent:
        raise ValueError(f"{source}: column(s) {absent} named in columns are not in the file")
    chosen = {v: k for k, v in mapping.items()}
    for name in ("time", *CHANNELS):
        if name not in chosen and name in available and name not in mapping:
            chosen[name] = name
    needed = ([] if rate is not None else ["time"]) + list(CHANNELS)
    missing = [c for c in needed if c not in chosen]
    if missing:
        hint = " (or give rate= for rows evenly spaced in time)" if missing == ["time"] else ""
        raise ValueError(
            f"{source}: no column for {missing}{hint}; the file has {available[:12]}; "
            "name the columns time, CV, P1, P2, T1, X, F or give a columns mapping"
        )
    if rate is not None and "time" in chosen:
        raise ValueError(f"{source}: has a time column; do not also give rate")
    ignored = [c for c in available if c not in chosen.values()]
    return chosen, ignored


def _rate_time(n: int, rate: float | None) -> np.ndarray:
    if rate is None or not (isinstance(rate, int | float) and rate > 0 and math.isfinite(rate)):
        raise ValueError(f"rate must be a positive number of samples per second, got {rate!r}")
    return np.arange(n, dtype=np.float64) / float(rate)


# ----------------------------------------------------------------------------------------------
# readers
# ----------------------------------------------------------------------------------------------
def read_csv(
    path: str | os.PathLike,
    *,
    columns: Mapping[str, str] | None = None,
    units: str | Mapping[str, str] = "normalised",
    resample: str | None = None,
    rate: float | None = None,
    delimiter: str | None = None,
    check_units: bool = True,
) -> xr.Dataset:
    """Read a CSV recording (see the module docstring for the rules).

    Parameters
    ----------
    path
        The file; a header row names the columns.
    columns
        File column -> channel (``time``, ``CV`` .. ``F``) for files with other names.
    units
        ``"normalised"``, ``"physical"`` or a mapping channel -> unit.
    resample
        ``None`` (a rate other than 1 Hz is an error), ``"mean"`` or ``"linear"``.
    rate
        Samples per second, for a file without a time column.
    delimiter
        Column separator; default ``","`` (``"\\t"`` for ``.tsv``).
    check_units
        Refuse values implausible in the declared units
        (`bayes_fdi.datasets.units.check_plausible_units`); ``False`` reads them as they are.

    Returns
    -------
    xarray.Dataset
        An unlabelled one-run dataset (attrs ``source``, ``format``, ``units``, ``gaps``,
        ``ignored_columns``, ``resampled``, ``sampling_step``, and for date-times
        ``time_origin``, with ``time_offsets`` where they carry UTC offsets).
    """
    source = os.fspath(path)
    if not os.path.exists(source):
        raise FileNotFoundError(2, "no such file", source)
    sep = delimiter or ("\t" if source.lower().endswith(".tsv") else ",")
    read = read_csv_columns(source, sep, lambda names: _pick_columns(names, columns, source, rate))
    time = read.time if read.time is not None else _rate_time(read.lines.size, rate)
    return _build(
        time, read.channels, units, resample, source, "csv", read.attrs, check_units, read.label
    )


def read_mat(
    path: str | os.PathLike,
    *,
    columns: Mapping[str, str] | None = None,
    units: str | Mapping[str, str] = "normalised",
    resample: str | None = None,
    rate: float | None = None,
    check_units: bool = True,
) -> xr.Dataset:
    """Read a MATLAB recording: one vector variable per channel (v5 via scipy, v7.3 via h5py).

    Parameters are those of :func:`read_csv`; ``columns`` maps variable names to channels.
    """
    import h5py

    source = os.fspath(path)
    if not os.path.exists(source):
        raise FileNotFoundError(2, "no such file", source)
    variables: dict[str, np.ndarray] = {}
    if h5py.is_hdf5(source):
        with h5py.File(source, "r") as handle:
            for key, item in handle.items():
                if isinstance(item, h5py.Dataset) and item.dtype.kind in "fiub":
                    variables[key] = np.asarray(item[()], dtype=np.float64)
        fmt = "mat-v7.3"
    else:
        from scipy.io import loadmat
        from scipy.io.matlab import MatReadError

        try:
            content = loadmat(source)
        except (MatReadError, ValueError, TypeError, OSError) as exc:
            raise ValueError(f"{source}: not a readable MATLAB file ({exc})") from None
        for key, value in content.items():
            if not key.startswith("__") and isinstance(value, np.ndarray):
                if value.dtype.kind in "fiub":
                    variables[key] = value.astype(np.float64)
        fmt = "mat"
    chosen, ignored = _pick_columns(list(variables), columns, source, rate)
    vectors = {}
    for name, var in chosen.items():
        value = variables[var]
        if value.ndim > 2 or (value.ndim == 2 and min(value.shape) != 1):
            raise ValueError(
                f"{source}: variable {var!r} has shape {value.shape}; expected a vector"
            )
        vectors[name] = value.ravel()
    lengths = {k: v.size for k, v in vectors.items()}
    if len(set(lengths.values())) != 1:
        raise ValueError(f"{source}: variables have different lengths {lengths}")
    n = next(iter(lengths.values()))
    time = vectors.pop("time") if "time" in vectors else _rate_time(n, rate)
    attrs = {"ignored_columns": json.dumps(ignored)}
    return _build(time, vectors, units, resample, source, fmt, attrs, check_units)


def read_netcdf(
    path: str | os.PathLike,
    *,
    columns: Mapping[str, str] | None = None,
    units: str | Mapping[str, str] = "normalised",
    resample: str | None = None,
    chunks: Mapping[str, int] | None = None,
    check_units: bool = True,
) -> xr.Dataset:
    """Read a netCDF recording (see the module docstring).

    Parameters are those of :func:`read_csv`, plus ``chunks`` (e.g. ``{"time": 86400}``): keep
    the data lazy in dask chunks (needs dask; the 1-s grid and units are checked, the values are
    read chunk by chunk by the diagnosis). A lazy recording must already be on the 1-s grid;
    its units are checked on its first :data:`LAZY_UNITS_SAMPLE` seconds. A dataset already in
    the project's format is taken as normalised (its units are not checked).
    """
    source = os.fspath(path)
    if not os.path.exists(source):
        raise FileNotFoundError(2, "no such file", source)
    try:
        with _bounded_chunk_cache(bool(chunks)):
            opened = xr.open_dataset(source, chunks=dict(chunks) if chunks else None)
            if chunks:  # open every variable now, with the bounded cache
                for name in opened.variables:
                    _ = opened.variables[name][(0,) * opened.variables[name].ndim].values
    except (OSError, ValueError, RuntimeError) as exc:
        raise ValueError(f"{source}: not a readable netCDF file ({exc})") from None
    if "run" in opened.dims and "time" in opened.dims and columns is None:
        return _project_dataset(opened, units, source, lazy=bool(chunks))
    if "time" not in opened.dims:
        raise ValueError(f"{source}: no 'time' dimension (dims are {tuple(opened.dims)})")
    names = [str(v) for v in opened.data_vars if opened[v].dims == ("time",)]
    chosen, ignored = _pick_columns([*names, "time"], columns, source, None)
    unit_of = parse_units(units)
    for name in CHANNELS:
        declared = opened[chosen[name]].attrs.get("units")
        if declared is not None and UNIT_ALIASES.get(str(declared), str(declared)) != unit_of[name]:
            raise ValueError(
                f"{source}: variable {chosen[name]!r} declares units {declared!r} but "
                f"{name} was given as {unit_of[name]!r} ('1' = normalised); pass units= to match"
            )
    time, origin = to_seconds(opened["time"].values, source)
    attrs = {"ignored_columns": json.dumps([c for c in ignored if c != "time"])}
    if origin:
        attrs["time_origin"] = origin
    if chunks:
        lazy = _lazy(opened, chosen, unit_of, time, source, attrs)
        if check_units:
            head = lazy.isel(time=slice(0, LAZY_UNITS_SAMPLE)).load()
            check_plausible_units(head, unit_of, source)
        return lazy
    raw = {name: np.asarray(opened[chosen[name]].values, dtype=np.float64) for name in CHANNELS}
    opened.close()
    return _build(time, raw, unit_of, resample, source, "netcdf", attrs, check_units)


#: Seconds at the start of a lazily read recording whose units are checked.
LAZY_UNITS_SAMPLE = 86400
#: Chunk cache (bytes) of each variable of a lazily read netCDF file: netCDF's default of 64 MB
#: per variable fills up as a long recording is read chunk by chunk (384 MB for six channels).
LAZY_CHUNK_CACHE = 16 * 2**20


@contextlib.contextmanager
def _bounded_chunk_cache(active: bool):
    """netCDF's default chunk cache set to :data:`LAZY_CHUNK_CACHE` while files are opened."""
    if not active:
        yield
        return
    import netCDF4

    previous = netCDF4.get_chunk_cache()
    netCDF4.set_chunk_cache(LAZY_CHUNK_CACHE, 1009, 0.75)
    try:
        yield
    finally:
        netCDF4.set_chunk_cache(*previous)


def _project_dataset(ds: xr.Dataset, units: Any, source: str, lazy: bool) -> xr.Dataset:
    """A file already in the project's format: normalised units only, labels kept."""
    if parse_units(units) != dict.fromkeys(CHANNELS, "1"):
        raise ValueError(f"{source}: a dataset in the project's format is normalised already")
    missing = [c for c in CHANNELS if c not in ds.data_vars]
    if missing:
        raise ValueError(f"{source}: lacks channel(s) {missing}")
    ds = ds[list(CHANNELS)]
    if not lazy:
        ds = ds.load()
        for name in ("state", "profile"):
            if name in ds.coords:
                ds = ds.assign_coords({name: ("run", ds[name].values.astype(str))})
        validate_dataset(ds, require=CHANNELS, allow_nan=True)
    ds.attrs.setdefault("source", source)
    ds.attrs["format"] = "netcdf"
    return ds


def _lazy(
    opened: xr.Dataset,
    chosen: Mapping[str, str],
    unit_of: Mapping[str, str],
    time: np.ndarray,
    source: str,
    attrs: dict,
) -> xr.Dataset:
    steps = np.diff(time)
    if time.size > 1 and (
        np.any(np.abs(steps - 1.0) > TIME_TOLERANCE) or not np.all(np.isfinite(time))
    ):
        raise ValueError(
            f"{source}: a lazily read recording must be sampled every 1 s without missing "
            "timestamps (write NaN rows for gaps); read it whole to resample"
        )
    data = {
        name: (
            ("run", "time"),
            normalise(opened[chosen[name]].data.astype(np.float64), name, unit_of[name])[None, :],
        )
        for name in CHANNELS
    }
    return xr.Dataset(
        data,
        coords={"run": [0], "time": time},
        attrs={
            "source": source,
            "format": "netcdf",
            "units": units_attribute(unit_of),
            "sampling_step": 1.0,
            "resampled": "no",
            **attrs,
        },
    )


def read_day_file(path: str | os.PathLike, *, actuator: int = 3) -> xr.Dataset:
    """Read a Lublin benchmark day file ``DDMM2001.txt`` for one actuator, unlabelled.

    `bayes_fdi.datasets.lublin.load_lublin_day` does the reading (the actuator's own ranges);
    its ``state`` label is dropped (the real faults of the day are in the ``fault_events``
    attribute instead, see :data:`~bayes_fdi.datasets.lublin.LUBLIN_FAULT_EVENTS`).
    """
    from bayes_fdi.datasets.lublin import load_lublin_day

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # re-warned below in this module's terms
        ds = load_lublin_day(path, actuator=actuator)
    ds = ds.drop_vars([c for c in ("state", "strength", "onset", "profile", "ramp") if c in ds])
    ds.attrs["format"] = "day"
    gaps = json.loads(ds.attrs["gaps"])
    warn_gaps(gaps, 0, os.fspath(path))
    return ds


def read_recording(
    path: str | os.PathLike, *, format: str | None = None, actuator: int = 3, **kwargs: Any
) -> xr.Dataset:
    """Read a recording with the reader its suffix names (:data:`FORMATS`) or ``format``.

    ``format`` is one of ``"csv"``, ``"mat"``, ``"netcdf"``, ``"day"``; ``actuator`` applies to
    day files; other keyword arguments go to the reader.
    """
    source = os.fspath(path)
    if format is None:
        suffix = os.path.splitext(source)[1].lower()
        if suffix not in FORMATS:
            raise ValueError(
                f"{source}: cannot tell the format from the suffix {suffix!r}; known suffixes "
                f"are {sorted(FORMATS)} (or give the format)"
            )
        format = FORMATS[suffix]
    if format == "day":
        if kwargs.get("units", "normalised") not in ("normalised", None) or kwargs.get("columns"):
            raise ValueError(f"{source}: a day file has fixed columns and units")
        if kwargs.get("resample"):
            raise ValueError(f"{source}: a day file is sampled at 1 Hz already")
        return read_day_file(source, actuator=actuator)
    readers = {"csv": read_csv, "mat": read_mat, "netcdf": read_netcdf}
    if format not in readers:
        raise ValueError(f"format must be one of {[*readers, 'day']}, got {format!r}")
    return readers[format](source, **{k: v for k, v in kwargs.items() if v is not None})
