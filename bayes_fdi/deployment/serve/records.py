"""One second's SEVA record as a flat row: the columns of the log and of the live page.

`row_from_update` makes the row of a second diagnosed by `OnlineDiagnoser.update` (its
`~bayes_fdi.diagnosis.seva.record.SevaRecord` and ``last_``); `rows_from_stream` makes the rows
of a gap diagnosed at once by ``OnlineDiagnoser.run`` (the same stream, by the library's
contract). `encode_state` and `decode_state` turn the diagnoser's
`~bayes_fdi.diagnosis.StreamState` into JSON text and back, bit for bit (the arrays' bytes in
base64), so a checkpoint can travel in a Parquet or netCDF file's metadata.
"""

from __future__ import annotations

import base64
import json
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import xarray as xr

from bayes_fdi.datasets import CHANNELS
from bayes_fdi.diagnosis import StreamState
from bayes_fdi.diagnosis.online.legacy import upgrade_stream_state

__all__ = [
    "FLOAT_COLUMNS",
    "ROW_COLUMNS",
    "decode_state",
    "encode_state",
    "group_labels",
    "row_from_update",
    "rows_from_stream",
]

#: Float columns of a row, besides the channels (normalised values as the diagnoser sees them).
FLOAT_COLUMNS: tuple[str, ...] = (
    "probability",
    "VMV_X",
    "VU_X",
    "VMV_F",
    "VU_F",
    "r_X",
    "r_F",
    "stat_X",
    "stat_F",
    "novelty",
)
#: Every column of a row, in the log's order (``group_proba`` is a vector over the groups;
#: ``received`` and ``published`` are wall-clock Unix times).
ROW_COLUMNS: tuple[str, ...] = (
    "time",
    *CHANNELS,
    "status",
    "state",
    *FLOAT_COLUMNS,
    "DD",
    "FFID",
    "group_proba",
    "reason",
    "note",
    "received",
    "published",
)


def group_labels(diagnoser: Any) -> tuple[str, ...]:
    """The labels of the diagnoser's isolability groups (the ``group_proba`` order)."""
    isolator = getattr(diagnoser, "isolator_", None)
    return tuple(isolator.group_labels_) if isolator is not None else ()


def row_from_update(
    record: Any,
    last: Mapping[str, Any],
    second: int,
    values: Mapping[str, float],
    notes: Sequence[str],
    received: float,
) -> dict[str, Any]:
    """The row of one second from ``update``'s record and ``last_``."""
    return {
        "time": int(second),
        **{c: float(values[c]) for c in CHANNELS},
        "status": record.status.value,
        "state": record.state,
        "probability": record.probability,
        "VMV_X": record.x_vmv,
        "VU_X": record.x_vu,
        "VMV_F": record.f_vmv,
        "VU_F": record.f_vu,
        "r_X": last["r_X"],
        "r_F": last["r_F"],
        "stat_X": last["stat_X"],
        "stat_F": last["stat_F"],
        "novelty": record.feature_novelty,
        "DD": bool(last["DD"]),
        "FFID": bool(last["FFID"]),
        "group_proba": np.asarray(last["group_proba"], dtype=np.float64),
        "reason": "; ".join(record.reasons),
        "note": "; ".join(notes),
        "received": float(received),
        "published": float("nan"),
    }


def rows_from_stream(
    stream: xr.Dataset, channels: xr.Dataset, first: int, notes: Sequence[str], reason: str
) -> list[dict[str, Any]]:
    """The rows of ``run``'s stream of consecutive seconds from ``first`` (notes on the first)."""
    n = stream.sizes["time"]
    columns = {c: np.asarray(channels[c].values, dtype=np.float64) for c in CHANNELS}
    columns |= {c: np.asarray(stream[c].values, dtype=np.float64) for c in FLOAT_COLUMNS}
    status = np.asarray(stream["status"].values).astype(str)
    state = np.asarray(stream["state"].values).astype(str)
    dd = np.asarray(stream["DD"].values, dtype=bool)
    ffid = np.asarray(stream["FFID"].values, dtype=bool)
    proba = np.asarray(stream["group_proba"].transpose("time", "group").values, dtype=np.float64)
    rows = []
    for i in range(n):
        row: dict[str, Any] = {"time": int(first + i)}
        row |= {c: float(v[i]) for c, v in columns.items()}
        row |= {
            "status": str(status[i]),
            "state": str(state[i]),
            "DD": bool(dd[i]),
            "FFID": bool(ffid[i]),
            "group_proba": proba[i].copy(),
            "reason": reason,
            "note": "; ".join(notes) if i == 0 else "",
            "received": float("nan"),
            "published": float("nan"),
        }
        rows.append(row)
    return rows


def _encode_array(a: np.ndarray) -> dict[str, Any]:
    a = np.ascontiguousarray(a)
    return {
        "dtype": a.dtype.str,
        "shape": list(a.shape),
        "data": base64.b64encode(a.tobytes()).decode("ascii"),
    }


def _decode_array(d: Mapping[str, Any]) -> np.ndarray:
    raw = base64.b64decode(d["data"])
    a = np.frombuffer(raw, dtype=np.dtype(d["dtype"])).reshape(d["shape"]).copy()
    a.flags.writeable = False
    return a


def encode_state(state: StreamState) -> str:
    """The stream state as JSON text (exact: the arrays' bytes, by their paths in the state)."""
    fields = {path: _encode_array(a) for path, a in state.arrays().items()}
    return json.dumps({"format": "bayes_fdi.StreamState", "version": 2, "fields": fields})


def decode_state(text: str) -> StreamState:
    """The `StreamState` of `encode_state`'s text (version 1, the flat state of earlier
    releases, is translated); a ``ValueError`` names a foreign text."""
    try:
        doc = json.loads(text)
        if doc.get("format") != "bayes_fdi.StreamState" or doc.get("version") not in (1, 2):
            raise ValueError("not a bayes_fdi stream state of version 1 or 2")
        fields = doc["fields"]
        if doc["version"] == 2:
            return StreamState.from_arrays({k: _decode_array(v) for k, v in fields.items()})
        values = {}
        for name, value in fields.items():
            if isinstance(value, list):
                values[name] = tuple(_decode_array(v) for v in value)
            else:
                values[name] = _decode_array(value)
        return StreamState(**upgrade_stream_state(values))
    except (KeyError, TypeError, json.JSONDecodeError) as exc:
        raise ValueError(f"corrupt stream state in the log ({exc})") from None
