"""The valves that share one model file in ``serve``: samples in, one SEVA record a second out for
each valve, all of them diagnosed in one call, resumable.

`ValveGroup` owns the model's `~bayes_fdi.diagnosis.OnlineDiagnoser`, one
`~bayes_fdi.deployment.serve.alignment.SecondAligner` per valve, and the stream state of every
valve stacked along a leading run axis (`~bayes_fdi.diagnosis.StreamState`, valve ``i`` is run
``i``):

- `offer` normalises a sample from its engineering unit (`bayes_fdi.datasets.units`) and
  places it on its valve's grid;
- `step` diagnoses every second the aligners have finished: the seconds of all the valves
  finished together go through **one** ``OnlineDiagnoser.run`` call over a one-second chunk of
  as many runs (only those valves' states advance; NaN for a missing channel: BLIND); a gap of
  one valve (``serve`` was down, or the plant's clock jumped) through ``run`` over NaN samples.
  Each valve's stream is the one ``update`` gives it second by second (the library's contract,
  tested against ``update`` here too);
- `checkpoints` snapshots the states after the valves' last seconds, for the log's commit (the
  texts are made later, in the log's writer thread); a group built from checkpoints continues
  each valve's stream exactly.

A gap longer than ``resume_max_gap`` (days of silence) starts a fresh stream for that valve
instead, and says so in the next record's note. A valve with its own model file is a group of
one.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping
from typing import Any

import numpy as np
import xarray as xr

from bayes_fdi.datasets import CHANNELS
from bayes_fdi.datasets.units import normalise
from bayes_fdi.deployment.serve.alignment import FinishedSecond, Gap, SecondAligner
from bayes_fdi.deployment.serve.durable_log import Checkpoint
from bayes_fdi.deployment.serve.records import decode_state, encode_states, stream_rows
from bayes_fdi.diagnosis import StreamState

__all__ = ["ValveGroup"]

Row = dict[str, Any]


class ValveGroup:
    """The valves of one model file (see the module docstring).

    Parameters
    ----------
    diagnoser
        The fitted `OnlineDiagnoser` of the model file (its ``update`` stream is not used).
    model_id
        Fingerprint of the model file (a checkpoint of another model is not resumed).
    valves
        Valve -> channel -> engineering unit of the values read from the plant (in run order).
    checkpoints
        The log's last checkpoint of each valve that has one.
    speed, max_delay, clock_tolerance
        Those of `SecondAligner`.
    resume_max_gap
        Longest gap (s) filled as BLIND seconds; a longer one starts a fresh stream.
    """

    def __init__(
        self,
        diagnoser: Any,
        model_id: str,
        valves: Mapping[str, Mapping[str, str]],
        checkpoints: Mapping[str, Checkpoint] | None = None,
        *,
        speed: float = 1.0,
        max_delay: float = 1.5,
        clock_tolerance: float = 5.0,
        resume_max_gap: int = 86_400,
    ) -> None:
        if not valves:
            raise ValueError("a valve group needs at least one valve")
        self.diagnoser = diagnoser
        self.model_id = model_id
        self.names = list(valves)
        self.index = {v: i for i, v in enumerate(self.names)}
        self.units = {v: dict(u) for v, u in valves.items()}
        self.resume_max_gap = int(resume_max_gap)
        self.fresh = diagnoser.reset().stream_state().run(0)
        self.last_second: dict[str, int | None] = {}
        self.startup_notes: dict[str, list[str]] = {}
        self.aligners: dict[str, SecondAligner] = {}
        states = []
        for v in self.names:
            state, resume_after = self._resumed(v, (checkpoints or {}).get(v))
            states.append(state)
            self.last_second[v] = resume_after
            self.aligners[v] = SecondAligner(
                CHANNELS,
                speed=speed,
                max_delay=max_delay,
                clock_tolerance=clock_tolerance,
                resume_after=resume_after,
            )
            for note in self.startup_notes[v]:
                self.aligners[v].note(note)
        self.state = StreamState.of_runs(states)
        # the first call loads the compiled kernels (about a second): not with the first data
        warm_up = {c: np.full((1, 2), 0.5) for c in CHANNELS}
        diagnoser.run(xr.Dataset({c: (("run", "time"), v) for c, v in warm_up.items()}))

    def _resumed(self, valve: str, checkpoint: Checkpoint | None) -> tuple[Any, int | None]:
        """The run state a valve starts from, and the last second already logged."""
        notes = self.startup_notes.setdefault(valve, [])
        if checkpoint is None:
            return self.fresh, None
        if checkpoint.model != self.model_id:
            notes.append(
                "the model file changed since the log's last record: a fresh stream starts"
            )
            return self.fresh, None
        state = decode_state(checkpoint.state)
        self.diagnoser.reset(state)  # checks the state against the model (a ValueError names it)
        self.diagnoser.reset()
        after = int(checkpoint.last_second)
        notes.append(f"resumed after the log's last second ({after})")
        return state.run(0), after

    # ------------------------------------------------------------------ input
    def offer(self, valve: str, channel: str, value: float, timestamp: float, wall: float) -> None:
        """A sample of ``valve`` in the channel's engineering unit (NaN: bad or missing)."""
        x = float(value)
        x = normalise(x, channel, self.units[valve][channel]) if math.isfinite(x) else math.nan
        self.aligners[valve].offer(channel, x, timestamp, wall)

    def note(self, valve: str, text: str) -> None:
        """Report an event with the valve's next record (e.g. the connection was lost)."""
        self.aligners[valve].note(text)

    def ready(self, valve: str) -> bool:
        """Whether the valve has a second to diagnose without waiting for a deadline."""
        return self.aligners[valve].ready()

    # ------------------------------------------------------------------ diagnosis
    def step(
        self, wall: float, to_unix: float, valves: Iterable[str] | None = None
    ) -> list[tuple[str, Row]]:
        """Diagnose every second finished by ``wall`` of ``valves`` (default: all); returns
        ``(valve, row)`` pairs, each valve's in order.

        ``to_unix`` converts the aligners' wall clock to Unix time (``received`` column).
        """
        chosen = self.names if valves is None else sorted(valves, key=self.index.__getitem__)
        due = {v: items for v in chosen if (items := self.aligners[v].due(wall))}
        rows: list[tuple[str, Row]] = []
        for j in range(max((len(items) for items in due.values()), default=0)):
            seconds = []
            for v, items in due.items():
                if j >= len(items):
                    continue
                if isinstance(items[j], Gap):
                    rows += [(v, row) for row in self._gap(v, items[j])]
                else:
                    seconds.append((v, items[j]))
            if seconds:
                rows += self._seconds(seconds, to_unix)
        return rows

    def _advance(self, runs: list[int], channels: Mapping[str, np.ndarray]) -> xr.Dataset:
        """``run`` over ``channels`` ``(len(runs), n)`` from the runs' states; the group's state
        gets the runs' new states."""
        chunk = xr.Dataset(
            {c: (("run", "time"), channels[c]) for c in CHANNELS},
            coords={"time": np.arange(next(iter(channels.values())).shape[1], dtype=np.float64)},
        )
        whole = runs == list(range(len(self.names)))
        state = self.state if whole else self.state.select_runs(runs)
        stream, state = self.diagnoser.run(chunk, state=state, return_state=True)
        self.state = state if whole else self.state.with_runs(runs, state)
        return stream

    def _seconds(self, seconds: list[tuple[str, FinishedSecond]], to_unix: float) -> list:
        """One second of each valve of ``seconds`` (valves in run order), in one ``run``."""
        runs = [self.index[v] for v, _ in seconds]
        channels = {c: np.array([[item.values[c]] for _, item in seconds]) for c in CHANNELS}
        stream = self._advance(runs, channels)
        out = []
        first = [item.second for _, item in seconds]
        for (v, item), (row,) in zip(seconds, stream_rows(stream, channels, first), strict=True):
            row["note"] = "; ".join(item.notes)
            if math.isfinite(item.received):
                row["received"] = item.received + to_unix
            self.last_second[v] = item.second
            out.append((v, row))
        return out

    def _gap(self, valve: str, gap: Gap) -> list[Row]:
        n = gap.last - gap.first + 1
        notes = list(gap.notes)
        i = self.index[valve]
        self.last_second[valve] = gap.last
        if n > self.resume_max_gap:
            self.state = self.state.with_runs([i], StreamState.of_runs([self.fresh]))
            notes.append(f"gap of {n} s > resume_max_gap: a fresh stream starts")
            self.aligners[valve].note("; ".join(notes))
            return []
        channels = {c: np.full((1, n), np.nan) for c in CHANNELS}
        stream = self._advance([i], channels)
        (rows,) = stream_rows(stream, channels, [gap.first])
        rows[0]["note"] = "; ".join(notes)
        return rows

    # ------------------------------------------------------------------ checkpoints
    def checkpoints(self, valves: Iterable[str]) -> Callable[[], dict[str, Checkpoint]]:
        """The valves' checkpoints as they stand now (those with a diagnosed second), made
        when the returned function is called (the state is immutable: any thread may)."""
        state, model = self.state, self.model_id
        chosen = [(v, self.index[v], s) for v in valves if (s := self.last_second[v]) is not None]

        def make() -> dict[str, Checkpoint]:
            if not chosen:
                return {}
            texts = encode_states(state.select_runs([i for _, i, _ in chosen]))
            return {
                v: Checkpoint(int(s), t, model) for (v, _, s), t in zip(chosen, texts, strict=True)
            }

        return make

    def checkpoint(self, valve: str) -> Checkpoint | None:
        """The valve's checkpoint now (None before its first second)."""
        return self.checkpoints([valve])().get(valve)
