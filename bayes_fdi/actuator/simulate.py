"""Simulate the actuator on a dataset of inputs; inject faults into real records."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import xarray as xr

from bayes_fdi.actuator import model
from bayes_fdi.actuator.faults import FAULT_NAMES, Fault
from bayes_fdi.actuator.parameters import P_RANGE, T_RANGE, ActuatorParameters, parameter_matrix
from bayes_fdi.datasets import CHANNELS, INPUT_CHANNELS, validate_dataset
from bayes_fdi.memory import check_memory

__all__ = ["NOISE_STD", "inject_faults", "simulate", "simulate_replicas"]

#: Standard deviation of DABLib's measurement noise (band-limited white noise of power 5e-9
#: sampled at 2.5 ms: sqrt(5e-9 / 0.0025)), in normalised full-scale units. DABLib also adds
#: 0.0025 sin(2 pi 50 t), which is exactly 0 at the 1 s sampling instants.
NOISE_STD = float(np.sqrt(5e-9 / 0.0025))

_SCALE = {"CV": 1.0, "P1": P_RANGE, "P2": P_RANGE, "T1": T_RANGE}
#: float64 values held per (run, second) at the peak of `simulate` / `inject_faults`: inputs (4),
#: model outputs (5) and states (4), noise (5), the output dataset (6) and its deep copy (6)
_VALUES_PER_SAMPLE = 30
#: order of the measured channels the kernel returns
_MEASURED = ("X", "F", "P1", "P2", "T1")
_HOLDS = {"zero": 0, "linear": 1}
_INTEGRATORS = {"reference": (0, model.STEPS_REF), "fast": (1, model.STEPS_REF)}


def _check_inputs(inputs: xr.Dataset, *, who: str, require=INPUT_CHANNELS) -> np.ndarray:
    """Validate the dataset (``require``: its channels); return physical inputs (run, time, 4)."""
    validate_dataset(inputs, require=require)
    time = np.asarray(inputs["time"].values, dtype=np.float64)
    if time.size < 1:
        raise ValueError(f"{who}: the dataset has no time samples")
    if inputs.sizes["run"] < 1:
        raise ValueError(f"{who}: the dataset has no runs")
    n_runs, n_t = inputs.sizes["run"], inputs.sizes["time"]
    check_memory(8.0 * _VALUES_PER_SAMPLE * n_runs * n_t, f"{who}: {n_runs} run(s) x {n_t} s")
    if time.size > 1 and not np.allclose(np.diff(time), 1.0):
        raise ValueError(f"{who}: the time coordinate must be 1 Hz (steps of 1 s)")
    u = np.empty((inputs.sizes["run"], inputs.sizes["time"], 4))
    for i, name in enumerate(INPUT_CHANNELS):
        values = inputs[name].transpose("run", "time").values
        low, high = float(values.min()), float(values.max())
        if low < 0.0 or high > 1.0:
            raise ValueError(
                f"{who}: channel {name} must be normalised to [0, 1], found [{low:g}, {high:g}]"
            )
        u[:, :, i] = values * _SCALE[name]
    reverse = u[:, :, 1] < u[:, :, 2]
    if reverse.any():
        r, t = np.argwhere(reverse)[0]
        raise ValueError(
            f"{who}: P1 < P2 at run {r}, t = {time[t]:g} s ({int(reverse.sum())} sample(s)); the "
            "DAMADICS valve model is defined for forward flow (P1 >= P2) only"
        )
    return np.ascontiguousarray(u)


def _validated(fault: Fault, r: int, who: str, n_t: int) -> Fault:
    try:
        checked = fault.validated()
    except ValueError as exc:
        raise ValueError(f"{who}: run {r}: {exc}") from None
    if checked.onset >= n_t:
        raise ValueError(
            f"{who}: run {r}: {checked.name} onset {checked.onset:g} s is at or after the run's "
            f"end ({n_t} s): the fault would be labelled but never simulated"
        )
    return checked


def _resolve_faults(inputs: xr.Dataset, faults, who: str) -> list[Fault | None]:
    n_runs = inputs.sizes["run"]
    n_t = inputs.sizes["time"]
    if faults is None:
        if "state" not in inputs.coords:
            return [None] * n_runs
        defaults = {"strength": 0.0, "onset": 0.0, "profile": "abrupt", "ramp": 0.0}
        coords = {
            name: inputs[name].values if name in inputs.coords else [default] * n_runs
            for name, default in defaults.items()
        }
        out: list[Fault | None] = []
        for r, state in enumerate(map(str, inputs["state"].values)):
            if state == "fn":
                out.append(None)
                continue
            fault = Fault(
                state,
                float(coords["strength"][r]),
                float(coords["onset"][r]),
                str(coords["profile"][r]),
                float(coords["ramp"][r]),
            )
            out.append(_validated(fault, r, who, n_t))
        return out
    if isinstance(faults, Fault):
        return [_validated(faults, 0, who, n_t)] * n_runs
    if isinstance(faults, str) or not isinstance(faults, Sequence):
        raise ValueError(
            f"{who}: faults must be None, a Fault or a sequence of Fault-or-None per run, "
            f"got {type(faults).__name__}"
        )
    if len(faults) != n_runs:
        raise ValueError(f"{who}: got {len(faults)} faults for {n_runs} runs")
    out = []
    for r, fault in enumerate(faults):
        if fault is None:
            out.append(None)
        elif isinstance(fault, Fault):
            out.append(_validated(fault, r, who, n_t))
        else:
            raise ValueError(f"{who}: faults[{r}] must be a Fault or None, got {fault!r}")
    return out


def _fault_arrays(faults: list[Fault | None]):
    n = len(faults)
    idx = np.full(n, -1, dtype=np.int64)
    strength = np.zeros(n)
    onset = np.zeros(n)
    ramp = np.zeros(n)
    for r, f in enumerate(faults):
        if f is not None:
            idx[r] = FAULT_NAMES.index(f.name)
            strength[r] = f.strength
            onset[r] = f.onset
            ramp[r] = f.ramp if f.profile == "incipient" else 0.0
    return idx, strength, onset, ramp


def _run_model(
    u: np.ndarray,
    faults: list[Fault | None],
    *,
    integrator: str,
    warmup: int,
    progress: bool,
    who: str,
    steps: int | None = None,
    hold: str = "linear",
    parameters: np.ndarray | None = None,
):
    """Run the compiled kernel: noise-free measured (run, time, 5) and states (run, time, 4).

    ``parameters``: the ``(run, VECTOR_SIZE)`` matrix of `parameter_matrix` (None: nominal).
    """
    if integrator not in _INTEGRATORS:
        raise ValueError(f"{who}: integrator must be 'fast' or 'reference', got {integrator!r}")
    if hold not in _HOLDS:
        raise ValueError(f"{who}: hold must be 'linear' or 'zero', got {hold!r}")
    if isinstance(warmup, bool) or not isinstance(warmup, int | np.integer) or warmup < 0:
        raise ValueError(f"{who}: warmup must be an integer number of seconds >= 0")
    idx, strength, onset, ramp = _fault_arrays(faults)
    n_runs, n_t = u.shape[:2]
    par = parameter_matrix(None, n_runs, who) if parameters is None else parameters
    out = np.empty((n_runs, n_t, 5))
    extra = np.empty((n_runs, n_t, 4))
    scheme, default_steps = _INTEGRATORS[integrator]
    steps = default_steps if steps is None else int(steps)
    chunk = n_runs if not progress else max(1, min(n_runs, 64))
    bar = None
    if progress:
        from bayes_fdi.progress import progress_bar

        bar = progress_bar(n_runs, f"simulating ({integrator})", unit="run")
    for start in range(0, n_runs, chunk):
        sl = slice(start, min(n_runs, start + chunk))
        model.simulate_batch(
            u[sl], idx[sl], strength[sl], onset[sl], ramp[sl], scheme, steps, _HOLDS[hold],
            int(warmup), par[sl],
            out[sl], extra[sl],
        )  # fmt: skip
        if bar is not None:
            bar.update(sl.stop - sl.start)
    if bar is not None:
        bar.close()
    return out, extra


def _noise(run_ids: np.ndarray, n_t: int, seed: int) -> np.ndarray:
    noise = np.empty((run_ids.size, n_t, 5))
    for r, run_id in enumerate(run_ids):
        rng = np.random.default_rng([int(seed), int(run_id)])
        noise[r] = rng.standard_normal((n_t, 5))
    return noise * NOISE_STD


def _with_fault_coords(ds: xr.Dataset, faults: list[Fault | None]) -> xr.Dataset:
    return ds.assign_coords(
        state=("run", np.array([f.name if f else "fn" for f in faults], dtype=str)),
        strength=("run", np.array([f.strength if f else 0.0 for f in faults])),
        onset=("run", np.array([f.onset if f else 0.0 for f in faults])),
        profile=("run", np.array([f.profile if f else "abrupt" for f in faults], dtype=str)),
        ramp=("run", np.array([f.ramp if f else 0.0 for f in faults])),
    )


def _states_dataset(ds: xr.Dataset, extra: np.ndarray) -> xr.Dataset:
    names = {
        "X_true": ("true stem position (fraction of closing)", "1"),
        "F_true": ("true flow through valve and bypass", "t/h"),
        "Ps": ("servomotor chamber gauge pressure", "Pa"),
        "CVI": ("positioner controller output (-1..1)", "1"),
    }
    data = {}
    for i, (name, (desc, unit)) in enumerate(names.items()):
        data[name] = xr.DataArray(
            extra[:, :, i], dims=("run", "time"), attrs={"long_name": desc, "units": unit}
        )
    return xr.Dataset(data, coords={c: ds.coords[c] for c in ds.coords})


def simulate(
    inputs: xr.Dataset,
    faults: Fault | Sequence[Fault | None] | None = None,
    seed: int = 0,
    *,
    integrator: str = "fast",
    hold: str = "linear",
    noise: bool = True,
    warmup: int = 30,
    progress: bool = False,
    return_states: bool = False,
    parameters: ActuatorParameters | Sequence[ActuatorParameters] | None = None,
):
    """Simulate the DAMADICS actuator driven by the inputs of a dataset.

    Parameters
    ----------
    inputs
        Dataset in the project's format (:mod:`bayes_fdi.datasets`) holding at least ``CV``,
        ``P1``, ``P2``, ``T1`` (normalised, 1 Hz, any number of runs, no NaN, ``P1 >= P2``).
        Other channels (e.g. the recorded ``X``, ``F`` of a real record) are replaced.
    faults
        ``None`` reads the per-run coordinates ``state``/``strength``/``onset``/``profile``/
        ``ramp`` of ``inputs`` when present (state ``"fn"`` = nominal), else simulates every
        run nominal; a single :class:`Fault` applies to every run; a sequence gives one
        ``Fault`` or ``None`` per run. Onsets are seconds from the run's first sample.
    seed
        Seed of the measurement noise. Run ``r`` uses the stream
        ``numpy.random.default_rng([seed, run_id])`` where ``run_id`` is its ``run``
        coordinate (its position if the coordinate is not a non-negative integer), so a run's
        noise does not depend on the other runs of the batch.
    integrator
        ``"fast"`` (default: 5 ms quasi-static implicit stem, with RK4 ticks for 50 ms after each
        input sample) or ``"reference"`` (DABLib's RK4 at 2.5 ms, about twice the cost). They
        agree to about 1e-4 of full scale RMS, far inside the measurement noise, except under
        large backlash (f4, f15), where they agree in distribution (see ``docs/actuator.md``).
    hold
        How the 1 Hz samples drive the model between samples: ``"linear"`` (default)
        interpolates linearly from each sample to the next (the default of Simulink's From
        Workspace block; with it the model reproduces the real hour to 2.0 % / 5.2 %
        RMS in X / F, against 2.8 % / 7.0 % with ``"zero"``); ``"zero"`` holds each sample for
        one second (zero-order hold, DGen's 1 s outputs taken literally).
    noise
        Add DABLib's measurement noise (std :data:`NOISE_STD` of full scale) to X, F, P1, P2,
        T1. CV, the controller output, is returned undisturbed.
    warmup
        Seconds simulated before ``t = 0`` with the first input sample held and no fault, so
        the runs start from the operating point rather than from DABLib's initial state
        (stem at 0, chamber at atmospheric pressure). ``warmup=0`` starts from that state.
    progress
        Show a progress bar (batches of 64 runs).
    return_states
        Also return an :class:`xarray.Dataset` of internal states at the 1 s instants:
        ``X_true`` (true stem position), ``F_true`` (true flow, t/h), ``Ps`` (chamber gauge
        pressure, Pa), ``CVI`` (positioner controller output).
    parameters
        The actuator's parameters: an `ActuatorParameters` for every run, or a sequence of
        them, one per run (None, the default: the nominal parameters, which reproduce DABLib's
        model). The recorded P1, P2, T1 are read through the parameters' sensor
        calibration (true value = (reading - offset) / gain) and the measured channels are
        returned through it.

    Returns
    -------
    xarray.Dataset or (xarray.Dataset, xarray.Dataset)
        A new dataset (``inputs`` is not modified) with ``X`` and ``F`` added and ``P1``,
        ``P2``, ``T1`` replaced by the measured values: noisy, clipped to ``[0, 1]`` and
        including what the faults do to them (f17 scales P1' or P2', f7 raises T1'). The fault
        coordinates describe the faults simulated; attrs ``seed`` and ``integrator`` are set.

    Examples
    --------
    >>> from bayes_fdi.actuator import Fault, benchmark_inputs, simulate
    >>> ds = simulate(benchmark_inputs(n_runs=2, duration=60), [None, Fault("f1", 0.75, 20.0)])
    >>> sorted(ds.data_vars), ds.state.values.tolist()
    (['CV', 'F', 'P1', 'P2', 'T1', 'X'], ['fn', 'f1'])
    """
    who = "simulate"
    _check_seed(seed, who)
    u = _check_inputs(inputs, who=who)
    resolved = _resolve_faults(inputs, faults, who)
    par = parameter_matrix(parameters, u.shape[0], who)
    out, extra = _run_model(
        u, resolved, integrator=integrator, warmup=warmup, progress=progress, who=who, hold=hold,
        parameters=par,
    )  # fmt: skip
    ds = _measured(inputs, out, resolved, seed, noise=noise, integrator=integrator, hold=hold)
    if return_states:
        return ds, _states_dataset(ds, extra)
    return ds


def _check_seed(seed, who: str) -> None:
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"{who}: seed must be an integer >= 0, got {seed!r}")


def _measured(
    inputs: xr.Dataset,
    clean: np.ndarray,
    resolved: list[Fault | None],
    seed: int,
    *,
    noise: bool,
    integrator: str,
    hold: str,
) -> xr.Dataset:
    """The measured dataset from the noise-free outputs ``clean`` (run, time, 5): noise, clip."""
    out = clean.copy()
    if noise:
        run_ids = np.asarray(inputs["run"].values)
        if not np.issubdtype(run_ids.dtype, np.integer) or (run_ids < 0).any():
            run_ids = np.arange(run_ids.size)  # non-integer run labels: use positions
        out += _noise(run_ids, out.shape[1], int(seed))
    np.clip(out, 0.0, 1.0, out=out)
    ds = inputs.copy(deep=True)  # the result shares no memory with the caller's dataset
    for i, name in enumerate(_MEASURED):
        ds[name] = (("run", "time"), out[:, :, i])
    ds = _with_fault_coords(ds[list(CHANNELS)], resolved)
    ds.attrs.update(seed=int(seed), integrator=integrator, hold=hold, noise=int(bool(noise)))
    ds.attrs.setdefault("bayes_fdi_version", inputs.attrs.get("bayes_fdi_version", ""))
    return validate_dataset(ds, require=CHANNELS)


def simulate_replicas(
    inputs: xr.Dataset,
    faults: Fault | Sequence[Fault | None] | None = None,
    seeds: Sequence[int] = (0,),
    *,
    integrator: str = "fast",
    hold: str = "linear",
    warmup: int = 30,
    progress: bool = False,
    parameters: ActuatorParameters | Sequence[ActuatorParameters] | None = None,
) -> list[xr.Dataset]:
    """Simulate once and return one noisy dataset per noise seed.

    The measurement noise is added to the model's outputs and never fed back into it, so the
    noise-free model is run once and each seed only draws its noise: ``simulate_replicas(
    inputs, faults, seeds)[i]`` equals ``simulate(inputs, faults, seed=seeds[i], ...)`` bit for
    bit, at the cost of one simulation instead of ``len(seeds)``.

    Parameters
    ----------
    inputs, faults, integrator, hold, warmup, progress, parameters
        As in :func:`simulate`.
    seeds
        Noise seeds (integers >= 0), as ``seed`` of :func:`simulate`.

    Returns
    -------
    list of xarray.Dataset
        One dataset per seed, in the order of ``seeds``.

    Examples
    --------
    >>> from bayes_fdi.actuator import benchmark_inputs, simulate, simulate_replicas
    >>> inputs = benchmark_inputs(n_runs=1, duration=30)
    >>> a, b = simulate_replicas(inputs, None, seeds=[3, 4])
    >>> a.X.equals(simulate(inputs, seed=3).X), b.X.equals(simulate(inputs, seed=4).X)
    (True, True)
    """
    who = "simulate_replicas"
    seeds = list(seeds)
    if not seeds:
        raise ValueError(f"{who}: give at least one seed")
    for seed in seeds:
        _check_seed(seed, who)
    u = _check_inputs(inputs, who=who)
    resolved = _resolve_faults(inputs, faults, who)
    par = parameter_matrix(parameters, u.shape[0], who)
    clean, _ = _run_model(
        u, resolved, integrator=integrator, warmup=warmup, progress=progress, who=who, hold=hold,
        parameters=par,
    )  # fmt: skip
    kw = {"noise": True, "integrator": integrator, "hold": hold}
    return [_measured(inputs, clean, resolved, int(s), **kw) for s in seeds]


def inject_faults(
    real: xr.Dataset,
    faults: Fault | Sequence[Fault | None] | None,
    *,
    seed: int | None = None,
    integrator: str = "fast",
    hold: str = "linear",
    warmup: int = 30,
    progress: bool = False,
    parameters: ActuatorParameters | Sequence[ActuatorParameters] | None = None,
) -> xr.Dataset:
    """Add faults to real records the way the paper did with DABLib.

    The model is driven twice by the recorded CV, P1, P2, T1 of every run, once nominal and once
    with the run's fault (both noise-free), and the difference of the measured channels
    (faulty minus nominal) is added to the recorded X and F, and to P1, P2, T1 where the fault
    changes what those sensors show (f17, f7). The recorded noise and the plant's own dynamics
    are kept; the result is clipped to ``[0, 1]`` like any measured channel. Before the fault's
    onset, and for strength 0, the record is returned unchanged.

    Parameters
    ----------
    real
        Real records in the project's format with ``CV, P1, P2, T1, X, F`` (no NaN: choose
        windows without gaps, see :func:`bayes_fdi.datasets.lublin.find_gaps`).
    faults
        As in :func:`simulate` (``None`` reads the dataset's fault coordinates).
    seed
        Stored in the ``seed`` attribute (the method itself is deterministic).
    integrator, hold, warmup, progress
        As in :func:`simulate`.
    parameters
        The model the differences are taken with: as in :func:`simulate` (one record, or one
        per run; e.g. a digital twin's parameters for the valve that made the records).

    Returns
    -------
    xarray.Dataset
        A new dataset with the faulty records and the fault coordinates set.
    """
    who = "inject_faults"
    u = _check_inputs(real, who=who, require=CHANNELS)
    resolved = _resolve_faults(real, faults, who)
    par = parameter_matrix(parameters, u.shape[0], who)
    kw = {
        "integrator": integrator,
        "warmup": warmup,
        "progress": progress,
        "who": who,
        "hold": hold,
    }
    faulty_idx = [r for r, f in enumerate(resolved) if f is not None]
    ds = real.copy(deep=True)  # the result shares no memory with the caller's dataset
    if faulty_idx:
        sub = u[faulty_idx]
        kw["parameters"] = par[faulty_idx]
        nominal, _ = _run_model(sub, [None] * len(faulty_idx), **kw)
        faulty, _ = _run_model(sub, [resolved[r] for r in faulty_idx], **kw)
        delta = faulty - nominal
        for i, name in enumerate(_MEASURED):
            values = np.array(real[name].transpose("run", "time").values, dtype=np.float64)
            values[faulty_idx] = np.clip(values[faulty_idx] + delta[:, :, i], 0.0, 1.0)
            ds[name] = (("run", "time"), values)
    ds = _with_fault_coords(ds, resolved)
    ds.attrs.update(
        integrator=integrator, hold=hold, injected="model difference (faulty - nominal)"
    )
    if seed is not None:
        ds.attrs["seed"] = int(seed)
    return validate_dataset(ds, require=CHANNELS)
