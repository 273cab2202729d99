"""One second's SEVA record as a flat row: the columns of the log and of the live page.

`stream_rows` makes the rows of the seconds ``OnlineDiagnoser.run`` diagnosed: one second of
many valves at once, or the seconds of a gap of one valve (the stream equals ``update``'s second
by second, by the library's contract, and so do the reasons). `encode_state` and `decode_state`
turn the diagnoser's `~bayes_fdi.diagnosis.StreamState` into JSON text and back, bit for bit (the
arrays' bytes in base64), so a checkpoint can travel in a Parquet or netCDF file's metadata;
`encode_states` gives one such text per run of a state of many runs.
"""

from __future__ import annotations

import base64
import json
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import xarray as xr

from bayes_fdi.datasets import CHANNELS
from bayes_fdi.diagnosis import StreamState
from bayes_fdi.diagnosis.online.legacy import upgrade_stream_state
from bayes_fdi.diagnosis.online.records import stream_reasons

__all__ = [
    "FLOAT_COLUMNS",
    "ROW_COLUMNS",
    "decode_state",
    "encode_state",
    "encode_states",
    "group_labels",
    "stream_rows",
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


def stream_rows(
    stream: xr.Dataset, channels: Mapping[str, np.ndarray], first: Sequence[int]
) -> list[list[dict[str, Any]]]:
    """The rows of ``OnlineDiagnoser.run``'s stream (dims ``run``, ``time``): per run, one row
    per second from its plant second ``first[r]`` on.

    ``channels`` are the ``(runs, time)`` normalised channels the stream was run on. The
    ``reason`` is the one ``update`` gives the second
    (`bayes_fdi.diagnosis.online.records.stream_reasons`); ``note`` is empty and ``received``
    and ``published`` are NaN (the caller's to fill).
    """
    n_runs, n_t = stream.sizes["run"], stream.sizes["time"]
    columns = {c: np.asarray(channels[c], dtype=np.float64).tolist() for c in CHANNELS}
    columns |= {c: stream[c].values.tolist() for c in FLOAT_COLUMNS}
    texts = {
        "status": np.asarray(stream["status"].values).astype(str).tolist(),
        "state": np.asarray(stream["state"].values).astype(str).tolist(),
        "reason": stream_reasons(stream).tolist(),
    }
    flags = {k: np.asarray(stream[k].values, dtype=bool).tolist() for k in ("DD", "FFID")}
    proba = np.asarray(
        stream["group_proba"].transpose("run", "time", "group").values, dtype=np.float64
    )
    out = []
    for r in range(n_runs):
        rows = []
        for t in range(n_t):
            row: dict[str, Any] = {"time": int(first[r]) + t}
            row |= {c: v[r][t] for c, v in columns.items()}
            row |= {k: v[r][t] for k, v in texts.items()}
            row |= {k: v[r][t] for k, v in flags.items()}
            row |= {
                "group_proba": proba[r, t].copy(),
                "note": "",
                "received": math.nan,
                "published": math.nan,
            }
            rows.append(row)
        out.append(rows)
    return out


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


def encode_states(state: StreamState) -> list[str]:
    """`encode_state` of each run of ``state`` (one text per run, each of a one-run state)."""
    arrays = state.arrays()
    texts = []
    for i in range(state.n_runs):
        fields = {path: _encode_array(a[i : i + 1]) for path, a in arrays.items()}
        texts.append(
            json.dumps({"format": "bayes_fdi.StreamState", "version": 2, "fields": fields})
        )
    return texts


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
