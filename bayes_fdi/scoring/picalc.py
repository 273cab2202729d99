"""The DAMADICS benchmark's performance indices (DABLib's PICalc block) from a 1 Hz decision stream.

Written by hand: PICalc is a Simulink block of DABLib v1.22 and no maintained Python library
computes the benchmark's indices. The definitions are those of the Benchmark Definition
([BD]: DAMADICS Research Training Network, Benchmark Definition v1.0, 2002, App. II) and the
DABLib manual ([MAN]: Bartyś & Syfert, DABLib v1.22, Warsaw University of Technology, 2002,
Table 35), summarised with their citations on the DAMADICS page of the documentation
(``docs/damadics.md``, "Performance indices").

Time zones (Step I): the set-up zone ``[0, t_on)`` is ignored; the benchmark zone is
``[t_on, t_hor)``, its fault-free part ``[t_on, t_from)`` and its faulty part ``[t_from, t_hor)``.
Every 1 Hz sample counts for one second.

Conventions copied from PICalc
------------------------------
- ``-1`` means "impossible to determine" (for example: never detected).
- Detection and isolation times run from ``t_from`` to the **last** rising edge of DD (PID)
  inside the benchmark zone: a detection is credited only once it is *permanent*.

Choices made where the benchmark's documents are silent (each is tested):

- A sample before ``t_on`` does not exist for the indices: DD high at ``t_on`` is a rising
  edge at ``t_on``.
- ``permanent=True`` (default): the last rising edge counts only if DD stays high up to the last
  second of the zone (``t_hor - 1``); a detection that is dropped for good before ``t_hor`` gives
  ``-1``. ``permanent=False`` takes the last rising edge of a high period reaching into the faulty
  part whatever follows it (the reading the worked example of [BD] App. IV needs, see the tests).
- A high period that began before ``t_from`` and lasts into the faulty part (a false alarm that
  persists) is credited at ``t_from``: ``t_dt = 0`` (PICalc's times range over
  ``[0, t_hor - t_on]``); ``r_fd`` shows the false alarm.
- A sample with no decision (NaN: a BLIND second, a gap in the record) counts as *low* for DD
  and PID and as 0 for CID: a gap inside a detection breaks it.
- ``fs_d`` / ``fs_i``: the fault strength at the credited edge (at ``t_from`` when the edge is
  earlier), read from the ``strength`` stream; ``-1`` without a strength stream.
- ``dacc = 1 / L``: ``L`` is the number of faults in the union of the elementary diagnoses
  (groups) indicated at any second from the moment of permanent true isolation (the credited
  PID edge, which for a detectable fault follows the DD edge because PID implies DD) to the end
  of the zone; ``-1`` without permanent isolation or without the ``indicated`` stream.

The docstring of `picalc` has an example.

Beside PICalc's indices, `first_detection` gives two of this package's own, which the benchmark
does not define: ``t_dt_first``, the time to the *first* detection in the faulty part, and
``dd_permanent``, whether DD stayed on from then to the end of the zone (``t_dt`` and
``t_dt_first`` agree exactly when it did).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = [
    "FIRST_DETECTION_KEYS",
    "FIRST_DETECTION_MEANINGS",
    "INDEX_MEANINGS",
    "PICALC_KEYS",
    "UNDETERMINED",
    "first_detection",
    "picalc",
]

#: What each PICalc index means, in plain words (for reports' glossaries).
INDEX_MEANINGS: tuple[tuple[str, str], ...] = (
    ("t_dt", "detection time: seconds from the fault's start to the (last, permanent) alarm"),
    ("r_fd", "false detection rate: share of the fault-free part with the alarm on"),
    ("r_td", "true detection rate: share of the faulty part with the alarm on"),
    ("fs_d", "fault detection sensitivity: the fault's strength when it was detected (0-1)"),
    ("t_it", "isolation time: seconds from the fault's start to naming its group for good"),
    ("r_fi", "false isolation rate: share of the fault-free part naming the fault's group"),
    ("r_ti", "true isolation rate: share of the faulty part naming the fault's group"),
    (
        "r_mi",
        "mismatch isolation rate: other groups named, per second of the zone on average (can "
        "exceed 1)",
    ),
    ("fs_i", "fault isolation sensitivity: the fault's strength when it was isolated (0-1)"),
    ("dacc", "diagnosis accuracy: 1 / the number of faults in the groups named after isolation"),
)

#: Keys of :func:`picalc`'s result, in the order of the benchmark's report form S1-FF.
PICALC_KEYS: tuple[str, ...] = (
    "t_dt",
    "r_fd",
    "r_td",
    "fs_d",
    "t_it",
    "r_fi",
    "r_ti",
    "r_mi",
    "fs_i",
    "dacc",
)
#: PICalc's value for an index that cannot be determined.
UNDETERMINED = -1.0
#: Keys of :func:`first_detection`'s result (not PICalc's: this package's own).
FIRST_DETECTION_KEYS: tuple[str, ...] = ("t_dt_first", "dd_permanent")
#: What each of :func:`first_detection`'s indices means, in plain words.
FIRST_DETECTION_MEANINGS: tuple[tuple[str, str], ...] = (
    (
        "t_dt_first",
        "first detection time: seconds from the fault's start to the first second of the "
        "faulty part with the alarm on (not a PICalc index; t_dt counts the last rising edge)",
    ),
    (
        "kept on",
        "the alarm stayed on from the first detection to the end of the zone (then t_dt = "
        "t_dt_first)",
    ),
)


def _zone_bounds(t_on: Any, t_from: Any, t_hor: Any) -> tuple[float, float, float]:
    values = []
    for name, v in (("t_on", t_on), ("t_from", t_from), ("t_hor", t_hor)):
        if isinstance(v, bool) or not isinstance(v, int | float | np.integer | np.floating):
            raise ValueError(f"picalc: {name} must be a real number of seconds, got {v!r}")
        if not math.isfinite(float(v)):
            raise ValueError(f"picalc: {name} must be finite, got {v!r}")
        values.append(float(v))
    on, start, hor = values
    if not on < start < hor:
        raise ValueError(f"picalc: need t_on < t_from < t_hor, got {on:g}, {start:g}, {hor:g}")
    for name, length in (("t_from - t_on", start - on), ("t_hor - t_from", hor - start)):
        if length != round(length):
            raise ValueError(f"picalc: {name} must be a whole number of seconds, got {length:g}")
    return on, start, hor


def _binary(values: Any, name: str, n: int) -> np.ndarray:
    """A 0/1 stream (bool, int or float; NaN = no decision = low) as a bool array."""
    a = np.asarray(values)
    if a.ndim != 1 or a.shape[0] != n:
        raise ValueError(f"picalc: {name} must be 1-D with one value per time sample ({n})")
    if a.dtype == bool:
        return a.copy()
    if not np.issubdtype(a.dtype, np.number):
        raise ValueError(f"picalc: {name} must be boolean or numeric, got dtype {a.dtype}")
    f = a.astype(np.float64)
    known = ~np.isnan(f)
    if not np.isin(f[known], (0.0, 1.0)).all():
        bad = f[known][~np.isin(f[known], (0.0, 1.0))][0]
        raise ValueError(f"picalc: {name} must hold 0/1 (or NaN for no decision), found {bad:g}")
    return known & (f == 1.0)


def _counts(values: Any, n: int) -> np.ndarray:
    a = np.asarray(values)
    if a.ndim != 1 or a.shape[0] != n:
        raise ValueError(f"picalc: cid must be 1-D with one value per time sample ({n})")
    if not (a.dtype == bool or np.issubdtype(a.dtype, np.number)):
        raise ValueError(f"picalc: cid must be numeric, got dtype {a.dtype}")
    f = a.astype(np.float64)
    f = np.where(np.isnan(f), 0.0, f)
    if (f < 0).any() or not np.isfinite(f).all() or (f != np.round(f)).any():
        raise ValueError("picalc: cid must hold whole numbers >= 0 (or NaN for no decision)")
    return f


def _credited_edge(high: np.ndarray, t: np.ndarray, t_from: float, permanent: bool) -> int | None:
    """Index (in the zone) of the last rising edge that counts, or None.

    The last high period of the zone is the candidate; it must reach the faulty part
    (``t >= t_from``) and, when ``permanent``, the zone's last sample.
    """
    if not high.any():
        return None
    last_high = int(np.flatnonzero(high)[-1])
    if t[last_high] < t_from or (permanent and last_high != high.size - 1):
        return None
    low_before = np.flatnonzero(~high[:last_high])
    start = int(low_before[-1]) + 1 if low_before.size else 0
    return max(start, int(np.searchsorted(t, t_from)))


def picalc(
    time: Any,
    dd: Any,
    pid: Any,
    cid: Any,
    *,
    t_on: float,
    t_from: float,
    t_hor: float,
    strength: Any = None,
    indicated: Any = None,
    group_sizes: Any = None,
    permanent: bool = True,
) -> dict[str, float]:
    """The DAMADICS performance indices of one scenario from its 1 Hz decision stream.

    Parameters
    ----------
    time
        Sample times (s), 1-D, increasing in steps of 1 s; the samples must cover the benchmark
        zone ``[t_on, t_hor)`` (samples outside it are ignored).
    dd, pid
        Detection decision and primary isolation decision per sample (bool, 0/1, or float
        with NaN for "no decision", which counts as low).
    cid
        Complementary isolation decision: the number of *other* diagnoses indicated
        (whole numbers >= 0; NaN counts as 0).
    t_on, t_from, t_hor
        Start of the benchmark zone, fault start, end of the zone (s); Step I uses 300, 900 and
        1500 (abrupt), 85 500, 5 100 or 2 400 (incipient).
    strength
        Fault strength per sample (the benchmark's ``fs`` stream, e.g. the magnitude of
        :meth:`bayes_fdi.actuator.Fault.value_at`), for ``fs_d`` and ``fs_i``.
    indicated, group_sizes
        For ``dacc``: the indicated elementary diagnoses per sample, bool of shape
        ``(n_time, n_groups)``, and the number of faults in each group (``n_groups`` whole
        numbers >= 1; for DGN0 count the OK state too, as [BD] App. II does).
    permanent
        Credit the last rising edge only when the decision stays high to the end of the zone
        (default, the benchmark's "detection must be permanent"); ``False`` credits the last
        rising edge of a high period reaching into the faulty part whatever follows it.

    Returns
    -------
    dict
        ``t_dt``, ``r_fd``, ``r_td``, ``fs_d``, ``t_it``, ``r_fi``, ``r_ti``, ``r_mi``, ``fs_i``,
        ``dacc`` (floats; :data:`UNDETERMINED` = -1 where PICalc cannot determine the index):

        - ``t_dt`` / ``t_it``: seconds from ``t_from`` to the credited rising edge of DD / PID;
        - ``r_fd`` / ``r_fi``: share of ``[t_on, t_from)`` with DD / PID high;
        - ``r_td`` / ``r_ti``: share of ``[t_from, t_hor)`` with DD / PID high;
        - ``r_mi``: ``sum(CID) / (t_hor - t_on)`` over the zone (can exceed 1);
        - ``fs_d`` / ``fs_i``: the strength at the credited edge;
        - ``dacc``: ``1 / L``, ``L`` the number of faults in the groups indicated from the
          credited PID edge to the end of the zone.

    Notes
    -----
    The conventions copied from PICalc and the choices made where the benchmark's documents
    are silent (a gap counts as low, a persisting false alarm is credited at ``t_from``, ...)
    are explained in the documentation's "DAMADICS benchmark (online)" page, "Performance
    indices (PICalc)".

    Examples
    --------
    An alarm raised 5 s after the fault and kept to the end of the zone:

    >>> import numpy as np
    >>> t = np.arange(0, 1500.0)
    >>> dd = t >= 905
    >>> out = picalc(t, dd, dd, np.zeros_like(t), t_on=300, t_from=900, t_hor=1500)
    >>> out["t_dt"], out["r_fd"], round(out["r_td"], 4)
    (5.0, 0.0, 0.9917)
    """
    on, start, hor = _zone_bounds(t_on, t_from, t_hor)
    t = np.asarray(time, dtype=np.float64)
    if t.ndim != 1 or t.size == 0:
        raise ValueError("picalc: time must be a non-empty 1-D array")
    if not np.isfinite(t).all():
        raise ValueError("picalc: time must be finite")
    if t.size > 1 and not np.allclose(np.diff(t), 1.0):
        raise ValueError("picalc: time must increase in steps of 1 s (a 1 Hz stream)")
    n = t.size
    zone = (t >= on) & (t < hor)
    n_zone = round(hor - on)
    if int(zone.sum()) != n_zone:
        raise ValueError(
            f"picalc: the stream ({t[0]:g} .. {t[-1]:g} s) does not cover the benchmark zone "
            f"[{on:g}, {hor:g}) s: {int(zone.sum())} of {n_zone} samples"
        )
    tz = t[zone]
    d = _binary(dd, "dd", n)[zone]
    p = _binary(pid, "pid", n)[zone]
    c = _counts(cid, n)[zone]
    fs = None
    if strength is not None:
        fs = np.asarray(strength, dtype=np.float64)
        if fs.shape != (n,) or not np.isfinite(fs).all():
            raise ValueError(f"picalc: strength must be {n} finite values, one per sample")
        fs = fs[zone]
    pre = tz < start
    n_pre, n_post = start - on, hor - start

    out: dict[str, float] = {}
    edges = {}
    for sig, (k_t, k_fa, k_true, k_fs) in (
        (d, ("t_dt", "r_fd", "r_td", "fs_d")),
        (p, ("t_it", "r_fi", "r_ti", "fs_i")),
    ):
        edge = _credited_edge(sig, tz, start, permanent)
        edges[k_t] = edge
        out[k_t] = UNDETERMINED if edge is None else float(tz[edge] - start)
        out[k_fa] = float(sig[pre].sum()) / n_pre
        out[k_true] = float(sig[~pre].sum()) / n_post
        out[k_fs] = UNDETERMINED if edge is None or fs is None else float(fs[edge])
    out["r_mi"] = float(c.sum()) / n_zone
    out["dacc"] = _dacc(indicated, group_sizes, zone, edges["t_it"], n)
    return {k: out[k] for k in PICALC_KEYS}


def _dacc(indicated: Any, group_sizes: Any, zone: np.ndarray, edge: int | None, n: int) -> float:
    if (indicated is None) != (group_sizes is None):
        raise ValueError("picalc: give both indicated and group_sizes (for dacc), or neither")
    if indicated is None:
        return UNDETERMINED
    ind = np.asarray(indicated)
    sizes = np.asarray(group_sizes)
    if ind.dtype != bool or ind.ndim != 2 or ind.shape[0] != n:
        raise ValueError(f"picalc: indicated must be a bool array of shape ({n}, n_groups)")
    if sizes.shape != (ind.shape[1],) or not np.issubdtype(sizes.dtype, np.integer):
        raise ValueError(f"picalc: group_sizes must be {ind.shape[1]} integers, one per group")
    if (sizes < 1).any():
        raise ValueError("picalc: every group must hold at least one fault (group_sizes >= 1)")
    if edge is None:
        return UNDETERMINED
    named = ind[zone][edge:].any(axis=0)
    n_faults = int(sizes[named].sum())
    return UNDETERMINED if n_faults == 0 else 1.0 / n_faults


def first_detection(
    time: Any, dd: Any, *, t_on: float, t_from: float, t_hor: float
) -> dict[str, float]:
    """The first detection of a fault and whether it was kept (not PICalc indices).

    Parameters
    ----------
    time, dd
        As for `picalc` (NaN in ``dd`` counts as low).
    t_on, t_from, t_hor
        The benchmark zone and the fault's start (s), as for `picalc`.

    Returns
    -------
    dict
        ``t_dt_first``: seconds from ``t_from`` to the first second of the faulty part
        ``[t_from, t_hor)`` with DD high (0 when an alarm raised earlier lasts into it);
        ``dd_permanent``: 1 when DD stays high from that second to the zone's last second,
        else 0. Both :data:`UNDETERMINED` when DD is never high in the faulty part.

    Examples
    --------
    Detected 5 s after the fault, dropped for one second at 1200 s, detected again:

    >>> import numpy as np
    >>> t = np.arange(0, 1500.0)
    >>> dd = (t >= 905) & (t != 1200)
    >>> first_detection(t, dd, t_on=300, t_from=900, t_hor=1500)
    {'t_dt_first': 5.0, 'dd_permanent': 0.0}
    >>> picalc(t, dd, dd, np.zeros_like(t), t_on=300, t_from=900, t_hor=1500)["t_dt"]
    301.0
    """
    _, start, hor = _zone_bounds(t_on, t_from, t_hor)
    t = np.asarray(time, dtype=np.float64)
    if t.ndim != 1 or t.size == 0 or not np.isfinite(t).all():
        raise ValueError("first_detection: time must be a non-empty finite 1-D array")
    faulty = (t >= start) & (t < hor)
    if int(faulty.sum()) != round(hor - start):
        raise ValueError(
            f"first_detection: the stream does not cover the faulty part [{start:g}, {hor:g}) s"
        )
    high = _binary(dd, "dd", t.size)[faulty]
    if not high.any():
        return {"t_dt_first": UNDETERMINED, "dd_permanent": UNDETERMINED}
    first = int(np.argmax(high))
    return {
        "t_dt_first": float(t[faulty][first] - start),
        "dd_permanent": float(high[first:].all()),
    }
