"""The SEVA record of one run, window or second, its status, and its conversions.

A :class:`SevaRecord` is immutable; :class:`SevaStatus` names the four statuses of a
self-validating device (Henry & Clarke 1993); :class:`ClassDistribution` is the record's
immutable class distribution. Records convert to pandas (:func:`to_frame`), xarray
(:func:`to_xarray`) and JSON (:func:`to_json`). The rules that choose a status are in
`bayes_fdi.diagnosis.seva.rules`.
"""

from __future__ import annotations

import enum
import json
import math
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import xarray as xr

__all__ = [
    "ClassDistribution",
    "SevaRecord",
    "SevaStatus",
    "to_frame",
    "to_json",
    "to_xarray",
]


class SevaStatus(enum.StrEnum):
    """Status of a self-validating actuator (Henry & Clarke 1993 naming)."""

    CLEAR = "CLEAR"
    BLURRED = "BLURRED"
    DAZZLED = "DAZZLED"
    BLIND = "BLIND"


class ClassDistribution(Mapping[str, float]):
    """Immutable, ordered mapping ``class label -> probability`` (picklable, hashable)."""

    __slots__ = ("_items",)

    def __init__(self, items: Mapping[str, float] | Sequence[tuple[str, float]]) -> None:
        pairs = items.items() if isinstance(items, Mapping) else items
        self._items = tuple((str(k), float(v)) for k, v in pairs)

    def __getitem__(self, key: str) -> float:
        for k, v in self._items:
            if k == key:
                return v
        raise KeyError(key)

    def __iter__(self) -> Iterator[str]:
        return (k for k, _ in self._items)

    def __len__(self) -> int:
        return len(self._items)

    def __hash__(self) -> int:
        return hash(self._items)

    def __eq__(self, other: object) -> bool:
        if isinstance(other, Mapping):
            return dict(self._items) == dict(other.items())
        return NotImplemented

    def __repr__(self) -> str:
        inner = ", ".join(f"{k!r}: {v:.3g}" for k, v in self._items)
        return f"ClassDistribution({{{inner}}})"

    def __reduce__(self):
        return (ClassDistribution, (self._items,))


@dataclass(frozen=True, slots=True)
class SevaRecord:
    """The SEVA output for one run or window (immutable).

    Attributes
    ----------
    run
        Run index (the dataset's ``run`` coordinate).
    t_start, t_end
        First and last time (s) of the window.
    x_measured, f_measured
        Mean measured X and F over the window's finite samples (NaN if none).
    x_vmv, f_vmv
        Validated measurement values: mean normal-model prediction of X and F.
    x_vu, f_vu
        Validated uncertainties: ``z * rms(predictive std)`` over the window, ``z`` the
        standard-normal quantile of ``coverage`` (the typical per-sample interval half-width,
        not the uncertainty of the window mean).
    coverage
        Central coverage of VMV ± VU (default 0.95).
    state
        Diagnosed state (the arg-max class; "" when none could be made).
    probability
        Probability of ``state``.
    distribution
        Full class distribution (class order of the diagnoser).
    entropy
        Normalised entropy ``H / log(n_classes)`` of ``distribution`` (0 certain, 1 uniform).
    status
        :class:`SevaStatus`.
    reasons
        Human-readable reasons for the status.
    missing_fraction, saturated_fraction
        Worst fraction over channels of missing and saturated samples.
    novel_fraction
        Fraction of window samples whose inputs are novel (NaN when not checked).
    feature_novelty
        Nearest-neighbour distance ratio of the run's feature vector (NaN when not checked).
    window
        Window index within the run for windowed diagnoses, else None.
    """

    run: int
    t_start: float
    t_end: float
    x_measured: float
    f_measured: float
    x_vmv: float
    x_vu: float
    f_vmv: float
    f_vu: float
    coverage: float
    state: str
    probability: float
    distribution: ClassDistribution
    entropy: float
    status: SevaStatus
    reasons: tuple[str, ...] = field(default=())
    missing_fraction: float = 0.0
    saturated_fraction: float = 0.0
    novel_fraction: float = math.nan
    feature_novelty: float = math.nan
    window: int | None = None

    def to_dict(self) -> dict[str, Any]:
        """Plain-Python dict (JSON-ready: status as its name, distribution as a dict)."""
        d = {f: getattr(self, f) for f in self.__dataclass_fields__}
        d["status"] = self.status.value
        d["distribution"] = dict(self.distribution)
        d["reasons"] = list(self.reasons)
        return d


# --------------------------------------------------------------------------------------
# conversions
# --------------------------------------------------------------------------------------
_SCALAR_FIELDS = (
    "run", "window", "t_start", "t_end", "x_measured", "f_measured", "x_vmv", "x_vu", "f_vmv",
    "f_vu", "coverage", "state", "probability", "entropy", "status", "missing_fraction",
    "saturated_fraction", "novel_fraction", "feature_novelty",
)  # fmt: skip


def _all_classes(records: Sequence[SevaRecord]) -> list[str]:
    classes: list[str] = []
    for r in records:
        for c in r.distribution:
            if c not in classes:
                classes.append(c)
    return classes


def _windowed(records: Sequence[SevaRecord]) -> bool:
    return any(r.window is not None for r in records)


def to_frame(records: Sequence[SevaRecord]):
    """A :class:`pandas.DataFrame`, one row per record.

    Indexed by ``run`` (or ``(run, window)`` for windowed records). The class distribution
    becomes columns ``p_<class>`` (NaN where absent); ``reasons`` is joined with ``"; "``;
    ``status`` is its string value.
    """
    import pandas as pd

    classes = _all_classes(records)
    windowed = _windowed(records)
    fields = [f for f in _SCALAR_FIELDS if windowed or f != "window"]
    rows = []
    for r in records:
        row = {f: getattr(r, f) for f in fields}
        row["status"] = r.status.value
        if windowed:
            row["window"] = -1 if r.window is None else r.window
        row.update({f"p_{c}": r.distribution.get(c, math.nan) for c in classes})
        row["reasons"] = "; ".join(r.reasons)
        rows.append(row)
    cols = [*fields, *(f"p_{c}" for c in classes), "reasons"]
    return pd.DataFrame(rows, columns=cols).set_index(["run", "window"] if windowed else "run")


def to_xarray(records: Sequence[SevaRecord]) -> xr.Dataset:
    """An :class:`xarray.Dataset` of the records.

    Dims ``run`` and ``class`` (windowed records: ``record`` and ``class``, with ``run`` and
    ``window`` coordinates on ``record``; window -1 for records without one). Scalar fields
    become variables along the first dim, the distribution ``proba (.., class)`` (NaN where
    absent), ``reasons`` a string variable.
    """
    classes = _all_classes(records)
    windowed = _windowed(records)
    dim = "record" if windowed else "run"
    data: dict[str, Any] = {}
    for f in _SCALAR_FIELDS:
        if f in ("run", "window", "state", "status"):
            continue
        data[f] = (dim, np.asarray([getattr(r, f) for r in records], dtype=np.float64))
    data["state"] = (dim, np.asarray([r.state for r in records], dtype=str))
    data["status"] = (dim, np.asarray([r.status.value for r in records], dtype=str))
    data["reasons"] = (dim, np.asarray(["; ".join(r.reasons) for r in records], dtype=str))
    proba = np.array([[r.distribution.get(c, math.nan) for c in classes] for r in records])
    data["proba"] = ((dim, "class"), proba.reshape(len(records), len(classes)))
    run = np.array([r.run for r in records], dtype=np.int64)
    coords: dict[str, Any] = {"class": np.asarray(classes, dtype=str)}
    if windowed:
        win = np.array([-1 if r.window is None else r.window for r in records], dtype=np.int64)
        coords |= {"run": (dim, run), "window": (dim, win)}
    else:
        coords["run"] = run
    return xr.Dataset(data, coords=coords)


def _json_safe(v: Any) -> Any:
    if isinstance(v, float) and not math.isfinite(v):
        return None
    if isinstance(v, dict):
        return {k: _json_safe(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_json_safe(x) for x in v]
    return v


def to_json(records: Sequence[SevaRecord], *, indent: int | None = 2) -> str:
    """JSON text: a list of :meth:`SevaRecord.to_dict` objects (NaN written as ``null``)."""
    return json.dumps([_json_safe(r.to_dict()) for r in records], indent=indent)
