"""Fault transplant: a fitted twin's fault signatures added to a valve's own healthy data.

For a run of healthy data and a parameter record (a posterior draw of the valve's twin), a
DAMADICS fault is transplanted by driving the twin with the run's own recorded CV, P1, P2, T1
twice, with and without the fault (noise-free), and adding the difference of every measured
channel (X, F, and P1, P2, T1 where the fault changes what those sensors show: f17, f7) to the
recorded data (`bayes_fdi.actuator.inject_faults` with the twin's parameters). The flow
sensor's fault f19 acts on the recorded flow exactly: ``F' <- F' - f (F' - o)``, i.e.
``o + (F' - o)(1 - f)`` with ``o`` the twin's F' offset (DABLib scales the reading, not the
model's flow). f13, the stem
sensor's fault, stays inside the positioner loop as DABLib defines it (model difference).

Faults of one measurement alone (:class:`MeasurementFault`, labels
`bayes_fdi.datasets.MEASUREMENT_FAULTS`): ``bias_X``, ``bias_F``, ``bias_P1``, ``bias_P2`` add
``strength * MEASUREMENT_BIAS_SCALE`` of full scale to that reading, from the onset on
(profile ``"abrupt"``: a bias) or growing linearly to it over ``ramp`` s (``"incipient"``: a
drift); the plant and the other readings are untouched. Every result is clipped to ``[0, 1]``
like a transmitter's output. :func:`transplant_library` draws a library of such runs.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import xarray as xr

from bayes_fdi.actuator import (
    FAULT_NAMES,
    ActuatorParameters,
    Fault,
    inject_faults,
)
from bayes_fdi.actuator.faults import fault_value
from bayes_fdi.datasets import CHANNELS, MEASUREMENT_FAULTS, make_dataset, validate_dataset
from bayes_fdi.twin.twin import ActuatorTwin

__all__ = [
    "MEASUREMENT_BIAS_SCALE",
    "STRENGTH_DRAWS",
    "MeasurementFault",
    "strength_slices",
    "transplant",
    "transplant_library",
]

#: Bias of a measurement fault of strength 1, in full-scale units (strength 0.1: 1 % of scale).
MEASUREMENT_BIAS_SCALE = 0.1
#: the reading each measurement fault acts on
MEASURED_CHANNEL = {name: name.split("_", 1)[1] for name in MEASUREMENT_FAULTS}
#: signs the library draws per fault (others: positive only); f4 < 0 only removes the nominal
#: 1 % backlash
SIGNS = {
    **{f: (-1.0, 1.0) for f in ("f12", "f13", "f14", "f17", "f19", *MEASUREMENT_FAULTS)},
}
#: The sign of run ``k`` of a signed fault in a library, times a sign drawn per fault: the
#: abrupt runs (even ``k``) and the incipient ones (odd ``k``) each alternate, so that every
#: profile meets both signs once a fault has four runs or more.
SIGN_PATTERN = (1.0, -1.0, -1.0, 1.0)
#: How a library draws each fault's strengths (`transplant_library`'s ``strength_draw``).
STRENGTH_DRAWS = ("uniform", "stratified")


def strength_slices(
    runs_per_fault: int, signed: bool, rng: np.random.Generator
) -> list[tuple[int, int]]:
    """The strength slice of each run of one fault in a library: ``(j, n)`` for run ``k``, its
    strength drawn uniformly in the ``j``-th of ``n`` equal slices of the strength range.

    The runs of one profile (abrupt for even ``k``, incipient for odd ``k``) and, for a signed
    fault, of one sign of `SIGN_PATTERN` form a cell; the ``n`` runs of a cell take the ``n``
    slices in an order ``rng`` draws (one permutation per cell, cells in order of first run).
    """
    cells: dict[tuple[int, float], list[int]] = {}
    for k in range(runs_per_fault):
        cells.setdefault((k % 2, SIGN_PATTERN[k % 4] if signed else 1.0), []).append(k)
    out = [(0, 1)] * runs_per_fault
    for members in cells.values():
        for k, j in zip(members, rng.permutation(len(members)), strict=True):
            out[k] = (int(j), len(members))
    return out


class MeasurementFault(NamedTuple):
    """A bias or drift of one reading alone (``name`` in `MEASUREMENT_FAULTS`).

    ``strength`` in ``[-1, 1]`` (the bias is ``strength * MEASUREMENT_BIAS_SCALE`` of full
    scale); ``onset``, ``profile`` and ``ramp`` as in `bayes_fdi.actuator.Fault` (incipient:
    a drift from 0 at ``onset`` to the full bias at ``onset + ramp``).
    """

    name: str
    strength: float
    onset: float = 0.0
    profile: str = "abrupt"
    ramp: float = 0.0

    def validated(self) -> MeasurementFault:
        """A checked copy; ``ValueError`` names the bad field."""
        if self.name not in MEASUREMENT_FAULTS:
            raise ValueError(
                f"MeasurementFault.name must be one of {MEASUREMENT_FAULTS}, got {self.name!r}"
            )
        # the field rules of a signed DAMADICS fault, checked by Fault and told in this name
        try:
            checked = Fault("f19", self.strength, self.onset, self.profile, self.ramp).validated()
        except ValueError as exc:
            message = str(exc).replace("Fault.", "MeasurementFault.").replace(" of f19", "")
            raise ValueError(message) from None
        return MeasurementFault(self.name, *checked[1:])

    def bias_at(self, t) -> np.ndarray:
        """The bias (full-scale units) at time(s) ``t`` s."""
        f = self.validated()
        return MEASUREMENT_BIAS_SCALE * fault_value(t, f.strength, f.onset, f.ramp)


def _validated(fault, r: int):
    if fault is None:
        return None
    if not isinstance(fault, Fault | MeasurementFault):
        raise ValueError(f"faults[{r}] must be a Fault, a MeasurementFault or None, got {fault!r}")
    try:
        return fault.validated()
    except ValueError as exc:
        raise ValueError(f"transplant: run {r}: {exc}") from None


def transplant(
    healthy: xr.Dataset,
    faults: Sequence[Fault | MeasurementFault | None],
    parameters: ActuatorParameters | Sequence[ActuatorParameters],
    *,
    integrator: str = "fast",
    hold: str = "linear",
    warmup: int = 30,
) -> xr.Dataset:
    """Transplant one fault into every run of healthy data.

    Parameters
    ----------
    healthy
        Healthy runs in the project's format (``CV, P1, P2, T1, X, F``, no NaN).
    faults
        One `Fault`, `MeasurementFault` or None (left healthy) per run; onsets in the run's
        time frame.
    parameters
        The twin's parameters: one record for every run, or one per run (posterior draws).
    integrator, hold, warmup
        As in `bayes_fdi.actuator.simulate`.

    Returns
    -------
    xarray.Dataset
        The faulty runs with coordinates ``state``, ``strength``, ``onset``, ``profile``,
        ``ramp``. A fault of strength 0 returns the run's data unchanged, bit for bit.
    """
    validate_dataset(healthy, require=CHANNELS)
    n_runs = healthy.sizes["run"]
    if isinstance(faults, Fault | MeasurementFault) or len(faults) != n_runs:
        raise ValueError(f"transplant: give one fault (or None) per run ({n_runs} runs)")
    resolved = [_validated(f, r) for r, f in enumerate(faults)]
    records = [parameters] * n_runs if isinstance(parameters, ActuatorParameters) else parameters
    if len(records) != n_runs:
        raise ValueError(f"transplant: got {len(records)} parameter records for {n_runs} runs")
    damadics = [f if isinstance(f, Fault) else None for f in resolved]
    ds = inject_faults(
        healthy.drop_vars([c for c in ("state", "strength", "onset", "profile", "ramp")
                           if c in healthy.coords]),
        damadics, parameters=list(records), integrator=integrator, hold=hold, warmup=warmup,
    )  # fmt: skip
    arrays = {c: ds[c].transpose("run", "time").values.copy() for c in CHANNELS}
    recorded_f = healthy["F"].transpose("run", "time").values
    time = np.asarray(healthy["time"].values, dtype=np.float64) - float(healthy["time"].values[0])
    for r, fault in enumerate(resolved):
        if isinstance(fault, Fault) and fault.name == "f19":
            offset = float(records[r].f_offset)
            value = fault_value(time, fault.strength, fault.onset, fault.ramp)
            arrays["F"][r] = np.clip(recorded_f[r] - value * (recorded_f[r] - offset), 0.0, 1.0)
        elif isinstance(fault, MeasurementFault):
            channel = MEASURED_CHANNEL[fault.name]
            recorded = healthy[channel].transpose("run", "time").values[r]
            arrays[channel][r] = np.clip(recorded + fault.bias_at(time), 0.0, 1.0)
    rows = [("fn", 0.0, 0.0, "abrupt", 0.0) if f is None else tuple(f) for f in resolved]
    state, strength, onset, profile, ramp = (list(column) for column in zip(*rows, strict=True))
    out = make_dataset(
        arrays, state=state, strength=strength, onset=onset, profile=profile, ramp=ramp,
        campaign="transplant",
        attrs={"integrator": integrator, "hold": hold, "method": "fault transplant"},
    )  # fmt: skip
    return out.assign_coords(time=healthy["time"].values)


class _Draw(NamedTuple):
    run: int
    start: int
    fault: Fault | MeasurementFault


def _valid_starts(healthy: xr.Dataset, duration: int) -> list[tuple[int, int]]:
    """(run, first sample) of every gap-free stretch of ``duration`` samples."""
    values = np.stack([healthy[c].transpose("run", "time").values for c in CHANNELS], axis=-1)
    out = []
    for run in range(values.shape[0]):
        bad = np.concatenate(([0], np.cumsum(~np.all(np.isfinite(values[run]), axis=-1))))
        starts = np.flatnonzero(bad[duration:] - bad[:-duration] == 0)
        out += [(run, int(s)) for s in starts]
    return out


def transplant_library(
    healthy: xr.Dataset,
    twin: ActuatorTwin | ActuatorParameters,
    *,
    faults: Sequence[str] = (*FAULT_NAMES, *MEASUREMENT_FAULTS),
    runs_per_fault: int = 4,
    duration: int = 600,
    strength: tuple[float, float] = (0.1, 1.0),
    onset: tuple[float, float] = (0.1, 0.5),
    ramp: tuple[float, float] = (60.0, 600.0),
    seed: int = 0,
    integrator: str = "fast",
    hold: str = "linear",
    warmup: int = 30,
    strength_draw: str = "uniform",
) -> xr.Dataset:
    """A library of fault runs transplanted into windows of a healthy recording.

    For fault ``i`` of ``faults`` and its run ``k``, the stream ``default_rng([seed, i, k])``
    draws: the window (``duration`` s, gap-free) uniformly inside the ``k``-th of
    ``runs_per_fault`` equal strata of the recording's possible starts, so each fault's onsets
    spread over the recording; the strength in ``strength`` (f4 positive, as the benchmark has
    it): with ``strength_draw="uniform"`` (default) uniformly, with ``"stratified"`` one draw in
    each of as many equal slices of the range as the fault has runs of that profile (and sign),
    in an order drawn per fault (`strength_slices`), so that every profile (and sign) meets both
    ends of the range (measured on the commissioning benchmark's selection plants, it did not
    name the faults better: see the commissioning page); the profile (abrupt for even ``k``,
    incipient for odd ``k``, with a ramp uniform in ``ramp`` s); the onset uniformly in
    ``onset`` (fractions of ``duration``, rounded to whole seconds); and the twin's parameters
    (one posterior draw; a fixed `ActuatorParameters` is used as is).
    The signed faults (f12, f13, f14, f17, f19 and the measurement faults) take the sign
    ``SIGN_PATTERN[k % 4]`` times one drawn per fault by ``default_rng([seed, i])``: every
    profile meets both signs once a fault has four runs (with a random sign per run, all the
    runs of a fault could share one sign, and a classifier trained on them never saw the
    other). Different seeds draw independent parameters, windows and faults; for training and
    evaluation sets that share no healthy data either, pass disjoint parts of the recording.

    Returns
    -------
    xarray.Dataset
        ``len(faults) * runs_per_fault`` runs of ``duration`` s in the project's format; attrs
        ``source_run`` and ``source_time`` give each window's run and first time (s) in
        ``healthy``.
    """
    names = list(faults)
    unknown = [f for f in names if f not in FAULT_NAMES and f not in MEASUREMENT_FAULTS]
    if unknown:
        raise ValueError(f"transplant_library: unknown fault(s) {unknown}")
    if not 0.0 <= strength[0] <= strength[1] <= 1.0:
        raise ValueError(f"strength must be a range inside [0, 1], got {strength!r}")
    if not 0.0 <= onset[0] <= onset[1] < 1.0:
        raise ValueError(f"onset must be a range of fractions inside [0, 1), got {onset!r}")
    if not 0.0 < ramp[0] <= ramp[1] or not math.isfinite(ramp[1]):
        raise ValueError(f"ramp must be a positive range of seconds, got {ramp!r}")
    starts = _valid_starts(healthy, int(duration))
    if len(starts) < runs_per_fault:
        raise ValueError(f"the recording has no {duration}-s gap-free windows to transplant into")
    if strength_draw not in STRENGTH_DRAWS:
        raise ValueError(f"strength_draw must be one of {STRENGTH_DRAWS}, got {strength_draw!r}")
    draws, records = [], []
    for i, name in enumerate(names):
        signs = SIGNS.get(name, (1.0,))
        fault_rng = np.random.default_rng([int(seed), i])
        flip = fault_rng.choice(signs)
        if strength_draw == "stratified":
            slices = strength_slices(int(runs_per_fault), len(signs) == 2, fault_rng)
        for k in range(int(runs_per_fault)):
            rng = np.random.default_rng([int(seed), i, k])
            stratum = len(starts) / runs_per_fault
            run, start = starts[int(k * stratum + rng.uniform(0.0, stratum))]
            sign = flip * SIGN_PATTERN[k % 4] if len(signs) == 2 else 1.0
            u = rng.uniform(0.0, 1.0)
            if strength_draw == "stratified":
                u = (slices[k][0] + u) / slices[k][1]
            value = (strength[0] + (strength[1] - strength[0]) * u) * sign
            t_on = float(round(rng.uniform(*onset) * duration))
            incipient = k % 2 == 1
            t_ramp = float(rng.uniform(*ramp)) if incipient else 0.0
            profile = "incipient" if incipient else "abrupt"
            kind = MeasurementFault if name in MEASUREMENT_FAULTS else Fault
            draws.append(_Draw(run, start, kind(name, float(value), t_on, profile, t_ramp)))
            if isinstance(twin, ActuatorTwin):
                records.append(twin.latent_to_parameters(twin.sample_latent(1, rng))[0])
            else:
                records.append(twin)
    windows = [
        healthy[list(CHANNELS)].isel(run=d.run, time=slice(d.start, d.start + int(duration)))
        for d in draws
    ]
    data = {c: np.stack([w[c].values for w in windows]) for c in CHANNELS}
    window_runs = make_dataset(data)
    out = transplant(
        window_runs, [d.fault for d in draws], records, integrator=integrator, hold=hold,
        warmup=warmup,
    )  # fmt: skip
    out.attrs.update(
        seed=int(seed),
        source_run=np.array([d.run for d in draws]),
        source_time=np.array([float(healthy["time"].values[d.start]) for d in draws]),
    )
    return out
