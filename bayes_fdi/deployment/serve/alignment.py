"""Samples of one valve placed on the 1 s grid of the plant's clock, second by second.

`SecondAligner` receives each channel's samples as they arrive (value, plant timestamp, wall
clock of arrival) and hands out, in order, every second of the stream:

- a second is **finished** as soon as its six channels are in, or when its **deadline** passes:
  ``max_delay`` wall-clock seconds after the time the plant's clock says it was due. A second
  finished by its deadline with channels missing is diagnosed with NaN for them: the diagnoser
  makes it BLIND. During a lost connection every second is finished by its deadline: BLIND,
  once per second, in real time.
- the plant's clock is followed by an **anchor**: the plant second and the wall-clock time of the
  last second that was complete, and ``speed`` plant seconds per wall-clock second (1 on a real
  plant; more for a simulated plant run faster than real time).
- a sample is placed at ``round(timestamp)`` (the nearest second). A second sample of a channel
  for a second is a **duplicate**: the first is kept, the other reported. A sample of a second
  already finished is **late**: reported, not merged (the second was published without it).
- a sample more than ``clock_tolerance`` plant seconds away from the anchor's prediction is a
  **clock jump**. Forward: once a whole second has arrived beyond the jump, the seconds skipped
  become a `Gap` (no data exist for them: BLIND) and the anchor moves. Backward: the samples lie
  in the stream's past; they are rejected and reported until the plant's clock catches up (a
  record's time never goes back; use a clock-synchronised plant server).
- at a restart the aligner continues after the last logged second (``resume_after``): the
  seconds between it and the first complete second are a `Gap` (``serve`` was down).

Every such event is a note attached to the next finished second (the log's ``note`` column).
Time is passed in (``wall``), never read here, so the tests can drive it exactly.

Written by hand: the grid, deadline and jump rules are this project's.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from collections.abc import Sequence
from typing import NamedTuple

__all__ = ["FinishedSecond", "Gap", "SecondAligner"]

#: Finished seconds remembered to tell a duplicate from a late sample.
_RECENT = 900
#: At most this many seconds ahead of the next one are held back (beyond: a clock jump).
_AHEAD_LIMIT = 4096


class FinishedSecond(NamedTuple):
    """One second of the stream, ready to diagnose."""

    second: int  #: plant time, integer Unix seconds
    values: dict[str, float]  #: channel -> value as read (NaN: missing)
    complete: bool  #: all channels arrived in time
    received: float  #: wall-clock time its last sample arrived (NaN: none)
    notes: tuple[str, ...]  #: events reported with this second


class Gap(NamedTuple):
    """Seconds ``first .. last`` (inclusive) without any data (BLIND), filled at once."""

    first: int
    last: int
    notes: tuple[str, ...]


class SecondAligner:
    """Alignment of one valve's samples on the 1 s grid (see the module docstring).

    Parameters
    ----------
    channels
        The channel names a second needs.
    speed
        Plant seconds per wall-clock second.
    max_delay
        Wall-clock seconds a second waits for its samples after it was due.
    clock_tolerance
        Plant seconds between a sample and the anchor's prediction beyond which the plant's
        clock is taken to have jumped.
    resume_after
        The last second already in the log (a restart), or None (a new stream).
    """

    def __init__(
        self,
        channels: Sequence[str],
        *,
        speed: float = 1.0,
        max_delay: float = 1.5,
        clock_tolerance: float = 5.0,
        resume_after: int | None = None,
    ) -> None:
        self.channels = tuple(channels)
        self.speed = float(speed)
        self.max_delay = float(max_delay)
        self.clock_tolerance = float(clock_tolerance)
        self.resume_after = resume_after
        self.next: int | None = None  #: the next second to finish (None: not started)
        self._anchor: tuple[int, float] | None = None
        self._pending: dict[int, dict[str, float]] = {}
        self._arrival: dict[int, float] = {}
        self._recent: OrderedDict[int, frozenset[str]] = OrderedDict()
        self._notes: list[str] = []
        self._gaps: list[Gap] = []
        self._behind_reported = False
        self.counts = {"duplicate": 0, "late": 0, "clock_jump": 0, "rejected": 0}

    # ------------------------------------------------------------------ input
    def note(self, text: str) -> None:
        """Attach an event (e.g. the connection was lost) to the next finished second."""
        self._notes.append(text)

    def predicted(self, wall: float) -> float | None:
        """The plant second the anchor predicts at wall-clock time ``wall``."""
        if self._anchor is None:
            return None
        second, at = self._anchor
        return second + (wall - at) * self.speed

    def offer(self, channel: str, value: float, timestamp: float, wall: float) -> None:
        """One sample of ``channel`` stamped ``timestamp`` (plant Unix s), arrived at ``wall``."""
        if channel not in self.channels:
            raise ValueError(f"unknown channel {channel!r}; channels are {self.channels}")
        if not math.isfinite(timestamp):
            self._notes.append(f"sample of {channel} without a timestamp: rejected")
            self.counts["rejected"] += 1
            return
        second = round(timestamp)
        if self.next is not None and second < self.next:
            self._past_sample(channel, second, wall)
            return
        if self.next is not None and second - self.next > _AHEAD_LIMIT + self.clock_tolerance:
            self._pending.clear()  # a jump this far: what was held is of the old clock
        slot = self._pending.setdefault(second, {})
        if channel in slot:
            self.counts["duplicate"] += 1
            same = slot[channel] == value or (math.isnan(slot[channel]) and math.isnan(value))
            kind = "same value" if same else f"value {value!r}, kept {slot[channel]!r}"
            self._notes.append(f"duplicate sample of {channel} at {_hms(second)} ({kind})")
            return
        slot[channel] = float(value)
        self._arrival[second] = wall
        if len(slot) == len(self.channels):
            self._complete(second, wall)

    def _past_sample(self, channel: str, second: int, wall: float) -> None:
        seen = self._recent.get(second)
        if seen is not None and channel in seen:
            self.counts["duplicate"] += 1
            self._notes.append(
                f"duplicate sample of {channel} at {_hms(second)} (after it was "
                "published): not merged"
            )
        elif seen is not None:
            self.counts["late"] += 1
            self._notes.append(
                f"late sample of {channel} at {_hms(second)} (published without it): not merged"
            )
        elif self.next - second <= self.clock_tolerance:
            self.counts["late"] += 1
            self._notes.append(
                f"late sample of {channel} at {_hms(second)} (before the stream "
                "went on): not merged"
            )
        else:
            self.counts["rejected"] += 1
            if not self._behind_reported:
                behind = self.next - second
                self._notes.append(
                    f"plant clock {behind} s behind the stream (sample of {channel} at "
                    f"{_hms(second)}): samples rejected until it catches up"
                )
                self._behind_reported = True
                self.counts["clock_jump"] += 1

    def _complete(self, second: int, wall: float) -> None:
        """A second has all its channels: start the stream, or check the clock and re-anchor."""
        if self.next is None:
            self._start(second, wall)
            return
        predicted = self.predicted(wall)
        if predicted is not None and second - predicted > self.clock_tolerance:
            self.counts["clock_jump"] += 1
            self._gap(
                self.next,
                second - 1,
                f"plant clock jumped forward by about {second - predicted:.0f} s: "
                f"{second - self.next} s without data",
            )
        self._behind_reported = False
        self._anchor = (second, wall)

    def _start(self, second: int, wall: float) -> None:
        dropped = sum(1 for s in self._pending if s < second)
        for s in [s for s in self._pending if s < second]:
            del self._pending[s]
            self._arrival.pop(s, None)
        if dropped:
            self._notes.append(f"{dropped} incomplete second(s) before the first complete one")
        self._anchor = (second, wall)
        after = self.resume_after
        if after is None:
            self.next = second
        elif second > after + 1:
            self.next = after + 1
            self._gap(
                after + 1,
                second - 1,
                f"no data for {second - after - 1} s (serve was down or the plant was silent)",
            )
        elif second <= after:
            self._notes.append(f"samples of {_hms(second)} are already in the log: rejected")
            self.counts["rejected"] += 1
            del self._pending[second]
            self._arrival.pop(second, None)
            self._anchor = None
        else:
            self.next = second

    def _gap(self, first: int, last: int, note: str) -> None:
        for s in [s for s in self._pending if s <= last]:
            del self._pending[s]
            self._arrival.pop(s, None)
        self._gaps.append(Gap(first, last, (*self._notes, note)))
        self._notes = []
        self.next = last + 1

    # ------------------------------------------------------------------ output
    def ready(self) -> bool:
        """Whether `due` has something now without waiting for a deadline."""
        if self._gaps:
            return True
        slot = self._pending.get(self.next) if self.next is not None else None
        return slot is not None and len(slot) == len(self.channels)

    def due(self, wall: float) -> list[FinishedSecond | Gap]:
        """Every second (and gap) finished by wall-clock time ``wall``, in order."""
        out: list[FinishedSecond | Gap] = list(self._gaps)
        self._gaps = []
        while self.next is not None and self._anchor is not None:
            second = self.next
            slot = self._pending.get(second)
            complete = slot is not None and len(slot) == len(self.channels)
            if not complete and wall < self._deadline(second):
                break
            out.append(self._finish(second, complete))
        return out

    def _deadline(self, second: int) -> float:
        anchor_second, at = self._anchor
        return at + (second - anchor_second) / self.speed + self.max_delay

    def _finish(self, second: int, complete: bool) -> FinishedSecond:
        slot = self._pending.pop(second, {})
        received = self._arrival.pop(second, math.nan)
        notes = self._notes
        self._notes = []
        if not complete:
            missing = [c for c in self.channels if c not in slot]
            notes.append(
                "no data" if len(missing) == len(self.channels) else f"missing {', '.join(missing)}"
            )
        values = {c: slot.get(c, math.nan) for c in self.channels}
        self._recent[second] = frozenset(slot)
        while len(self._recent) > _RECENT:
            self._recent.popitem(last=False)
        self.next = second + 1
        return FinishedSecond(second, values, complete, received, tuple(notes))


def _hms(second: int) -> str:
    """A plant second as an ISO UTC time (for the notes)."""
    import datetime as dt

    return dt.datetime.fromtimestamp(second, dt.UTC).strftime("%Y-%m-%dT%H:%M:%SZ")
