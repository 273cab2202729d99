"""One valve's loop in ``serve``: samples in, one SEVA record a second out, resumable.

`ValveRunner` owns a valve's `~bayes_fdi.diagnosis.OnlineDiagnoser`, its
`~bayes_fdi.deployment.serve.alignment.SecondAligner` and its last checkpoint:

- `offer` normalises a sample from its engineering unit (`bayes_fdi.datasets.units`) and
  places it on the grid;
- `step` diagnoses every second the aligner has finished: a second through ``update`` (NaN for
  a missing channel: BLIND), a gap (``serve`` was down, or the plant's clock jumped) through the
  batch ``run`` over NaN samples, which gives the same stream as ``update`` second by second
  (the library's contract) in one call;
- `checkpoint` is the stream state after the last second, saved with the log's commit; a
  runner built from a checkpoint continues that stream exactly (`OnlineDiagnoser.reset`).

A gap longer than ``resume_max_gap`` (days of silence) starts a fresh stream instead, and says
so in the record's note.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np
import xarray as xr

from bayes_fdi.datasets import CHANNELS
from bayes_fdi.datasets.units import normalise
from bayes_fdi.deployment.serve.alignment import FinishedSecond, Gap, SecondAligner
from bayes_fdi.deployment.serve.durable_log import Checkpoint
from bayes_fdi.deployment.serve.records import (
    decode_state,
    encode_state,
    row_from_update,
    rows_from_stream,
)

__all__ = ["ValveRunner"]

#: Gaps up to this long are diagnosed second by second with ``update``, longer ones with ``run``.
_UPDATE_GAP = 8


class ValveRunner:
    """The per-second loop of one valve (see the module docstring).

    Parameters
    ----------
    name
        The valve's name.
    diagnoser
        Its fitted `OnlineDiagnoser` (its stream is reset here).
    units
        Channel -> engineering unit of the values read from the plant.
    model_id
        Fingerprint of the model file (a checkpoint of another model is not resumed).
    checkpoint
        The log's last checkpoint of this valve, or None.
    speed, max_delay, clock_tolerance
        Those of `SecondAligner`.
    resume_max_gap
        Longest gap (s) filled as BLIND seconds; a longer one starts a fresh stream.
    """

    def __init__(
        self,
        name: str,
        diagnoser: Any,
        units: Mapping[str, str],
        model_id: str,
        checkpoint: Checkpoint | None = None,
        *,
        speed: float = 1.0,
        max_delay: float = 1.5,
        clock_tolerance: float = 5.0,
        resume_max_gap: int = 86_400,
    ) -> None:
        self.name = name
        self.diagnoser = diagnoser
        self.units = dict(units)
        self.model_id = model_id
        self.resume_max_gap = int(resume_max_gap)
        self.startup_notes: list[str] = []
        resume_after = None
        diagnoser.reset()
        if checkpoint is not None and checkpoint.model != model_id:
            self.startup_notes.append(
                "the model file changed since the log's last record: a fresh stream starts"
            )
        elif checkpoint is not None:
            diagnoser.reset(decode_state(checkpoint.state))
            resume_after = int(checkpoint.last_second)
            self.startup_notes.append(f"resumed after the log's last second ({resume_after})")
        self.last_second = resume_after
        self.aligner = SecondAligner(
            CHANNELS,
            speed=speed,
            max_delay=max_delay,
            clock_tolerance=clock_tolerance,
            resume_after=resume_after,
        )
        for note in self.startup_notes:
            self.aligner.note(note)

    def offer(self, channel: str, value: float, timestamp: float, wall: float) -> None:
        """A sample in the channel's engineering unit (NaN: bad or missing)."""
        x = float(value)
        x = normalise(x, channel, self.units[channel]) if math.isfinite(x) else math.nan
        self.aligner.offer(channel, x, timestamp, wall)

    def note(self, text: str) -> None:
        """Report an event with the next record (e.g. the connection was lost)."""
        self.aligner.note(text)

    def step(self, wall: float, to_unix: float) -> list[dict[str, Any]]:
        """Diagnose every second finished by ``wall``; returns their rows.

        ``to_unix`` converts the aligner's wall clock to Unix time (``received`` column).
        """
        rows: list[dict[str, Any]] = []
        for item in self.aligner.due(wall):
            if isinstance(item, Gap):
                rows += self._gap(item)
            else:
                rows.append(self._second(item, to_unix))
        return rows

    def _second(self, item: FinishedSecond, to_unix: float) -> dict[str, Any]:
        record = self.diagnoser.update({**item.values, "time": float(item.second)})
        received = item.received + to_unix if math.isfinite(item.received) else math.nan
        self.last_second = item.second
        return row_from_update(
            record, self.diagnoser.last_, item.second, item.values, item.notes, received
        )

    def _gap(self, gap: Gap) -> list[dict[str, Any]]:
        n = gap.last - gap.first + 1
        notes = list(gap.notes)
        if n > self.resume_max_gap:
            self.diagnoser.reset()
            notes.append(f"gap of {n} s > resume_max_gap: a fresh stream starts")
            self.last_second = gap.last
            self.aligner.note("; ".join(notes))
            return []
        nan = dict.fromkeys(CHANNELS, math.nan)
        if n <= _UPDATE_GAP:
            rows = []
            for i in range(n):
                item = FinishedSecond(
                    gap.first + i, nan, False, math.nan, tuple(notes) if i == 0 else ()
                )
                rows.append(self._second(item, 0.0))
            return rows
        channels = xr.Dataset(
            {c: ("time", np.full(n, np.nan)) for c in CHANNELS},
            coords={"time": np.arange(gap.first, gap.last + 1, dtype=np.float64)},
        )
        stream, state = self.diagnoser.run(
            channels, state=self.diagnoser.stream_state(), return_state=True
        )
        self.diagnoser.reset(state)
        self.last_second = gap.last
        return rows_from_stream(stream, channels, gap.first, notes, "no data (gap)")

    def checkpoint(self) -> Checkpoint | None:
        """The stream state after the last diagnosed second (None before the first)."""
        if self.last_second is None:
            return None
        state = encode_state(self.diagnoser.stream_state())
        return Checkpoint(int(self.last_second), state, self.model_id)
