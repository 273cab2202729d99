"""The actuator simulator as the twin sees it: fit windows, batched runs, a finite-difference slope.

A healthy recording is cut into gap-free windows (:func:`cut_windows`); each window is simulated
as its own run from its first sample (after the simulator's warm-up), so the windows of a
recording, and the parameter sets of a batch, run in parallel on the CPU cores. The simulator
is compiled numba code, not differentiable in torch: :func:`simulated_outputs` wraps it as a
torch autograd function whose derivative is a central finite difference taken over a stated
step (a secant over the simulator's non-smooth parts: dead zone, backlash, clipping), so a Pyro
model can call it and torch can form gradients and Gauss-Newton curvatures through it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import torch
import xarray as xr

from bayes_fdi.actuator import PARAMETER_INFO, ActuatorParameters, simulate
from bayes_fdi.datasets import CHANNELS, INPUT_CHANNELS, make_dataset, validate_dataset

__all__ = ["FitWindows", "WindowSimulator", "cut_windows", "simulated_outputs"]

#: the channels the twin is fitted to, in the order of the last axis of its arrays
OUTPUTS: tuple[str, ...] = ("X", "F")
#: windows shorter than this many usable samples are not fitted on
MIN_WINDOW = 60


class FitWindows(NamedTuple):
    """Windows of a recording, ready to simulate.

    ``inputs``: a dataset of ``W`` runs of ``T`` samples (windows padded at the end by holding
    their last sample); ``observed``: ``(W, T, 2)`` recorded X, F; ``mask``: ``(W, T)`` the
    samples that count (after the settling time, before the padding); ``origin``: ``(run,
    first time)`` of each window in the recording.
    """

    inputs: xr.Dataset
    observed: np.ndarray
    mask: np.ndarray
    origin: tuple[tuple[int, float], ...]


def _segments(finite: np.ndarray) -> list[tuple[int, int]]:
    edges = np.diff(np.concatenate(([0], finite.astype(np.int8), [0])))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1), strict=True))


def cut_windows(
    healthy: xr.Dataset, *, window: int, settle: int, max_seconds: int | None
) -> FitWindows:
    """Cut the gap-free parts of every run into windows of ``window`` s (the last may be shorter).

    ``settle`` s at each window's start are simulated but not fitted (the model starts from the
    first sample's operating point, the plant was moving). If the windows hold more than
    ``max_seconds`` s, evenly spaced windows are kept: ``ceil(max_seconds / window)`` of them,
    at positions ``round(linspace(0, n - 1, k))``. Raises ``ValueError`` when nothing is left.
    """
    validate_dataset(healthy, require=CHANNELS, allow_nan=True)
    if window < MIN_WINDOW + settle:
        raise ValueError(f"window must be at least {MIN_WINDOW + settle} s, got {window}")
    values = np.stack([healthy[c].transpose("run", "time").values for c in CHANNELS], axis=-1)
    times = np.asarray(healthy["time"].values, dtype=np.float64)
    pieces = []
    for run in range(values.shape[0]):
        for a, b in _segments(np.all(np.isfinite(values[run]), axis=-1)):
            for start in range(a, b, window):
                stop = min(b, start + window)
                if stop - start >= MIN_WINDOW + settle:
                    pieces.append((run, start, stop))
    if not pieces:
        raise ValueError(
            f"no gap-free stretch of at least {MIN_WINDOW + settle} s to fit the twin on"
        )
    if max_seconds is not None and sum(b - a for _, a, b in pieces) > max_seconds:
        k = min(len(pieces), -(-int(max_seconds) // window))
        keep = np.unique(np.round(np.linspace(0, len(pieces) - 1, k)).astype(int))
        pieces = [pieces[i] for i in keep]
    n_t = max(b - a for _, a, b in pieces)
    arrays = np.empty((len(pieces), n_t, len(CHANNELS)))
    mask = np.zeros((len(pieces), n_t), dtype=bool)
    for w, (run, a, b) in enumerate(pieces):
        arrays[w, : b - a] = values[run, a:b]
        arrays[w, b - a :] = values[run, b - 1]
        mask[w, settle : b - a] = True
    inputs = make_dataset(
        {c: arrays[:, :, i] for i, c in enumerate(CHANNELS)}, campaign="twin-fit-windows"
    )
    observed = arrays[:, :, [CHANNELS.index(c) for c in OUTPUTS]]
    origin = tuple((int(run), float(times[a])) for run, a, _ in pieces)
    return FitWindows(inputs, observed, mask, origin)


class WindowSimulator:
    """Noise-free X', F' of the windows under parameter sets that change some fields of ``base``.

    Parameters
    ----------
    inputs
        Dataset of ``W`` runs with ``CV, P1, P2, T1`` (e.g. `FitWindows.inputs`).
    base
        The parameters the fitted fields ``names`` replace.
    names
        The fitted fields, in the order of the vectors ``theta``.
    simulate_options
        ``integrator``, ``hold``, ``warmup`` of `bayes_fdi.actuator.simulate`.
    """

    def __init__(
        self,
        inputs: xr.Dataset,
        base: ActuatorParameters,
        names: Sequence[str],
        **simulate_options,
    ) -> None:
        self.inputs = inputs[list(INPUT_CHANNELS)]
        self.base = base.validated()
        self.names = tuple(names)
        self.options = dict(simulate_options)
        self.n_windows = int(inputs.sizes["run"])
        self.n_times = int(inputs.sizes["time"])
        self._tiled: dict[int, xr.Dataset] = {}

    def parameters(self, theta: np.ndarray) -> ActuatorParameters:
        """The full parameter record of one vector ``theta`` (validated)."""
        values = dict(zip(self.names, (float(v) for v in theta), strict=True))
        return self.base._replace(**values).validated()

    def outputs(self, thetas: np.ndarray) -> np.ndarray:
        """``(B, W, T, 2)`` clipped, noise-free X', F' for the ``(B, p)`` vectors ``thetas``."""
        thetas = np.atleast_2d(np.asarray(thetas, dtype=np.float64))
        n_sets = thetas.shape[0]
        if n_sets not in self._tiled:
            runs = np.tile(np.arange(self.n_windows), n_sets)
            self._tiled[n_sets] = self.inputs.isel(run=runs).assign_coords(run=np.arange(runs.size))
        records = [self.parameters(t) for t in thetas for _ in range(self.n_windows)]
        ds = simulate(self._tiled[n_sets], noise=False, parameters=records, **self.options)
        out = np.stack([ds[c].transpose("run", "time").values for c in OUTPUTS], axis=-1)
        return out.reshape(n_sets, self.n_windows, self.n_times, len(OUTPUTS))

    def jacobian(self, theta: np.ndarray, steps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Outputs at ``theta`` ``(W, T, 2)`` and their central-difference slopes ``(W, T, 2, p)``.

        Parameter ``i`` is moved by ``-+steps[i]``, within its physical bounds (a one-sided
        difference over the part of the step inside them).
        """
        theta = np.asarray(theta, dtype=np.float64)
        p = theta.size
        lows = np.array([PARAMETER_INFO[n].low for n in self.names])
        highs = np.array([PARAMETER_INFO[n].high for n in self.names])
        minus = np.maximum(theta - steps, lows)
        plus = np.minimum(theta + steps, highs)
        sets = np.repeat(theta[None], 1 + 2 * p, axis=0)
        for i in range(p):
            sets[1 + 2 * i, i] = minus[i]
            sets[2 + 2 * i, i] = plus[i]
        out = self.outputs(sets)
        slopes = (out[2::2] - out[1::2]) / (plus - minus)[:, None, None, None]
        return out[0], np.moveaxis(slopes, 0, -1)


class _SimulatedOutputs(torch.autograd.Function):
    """Simulator outputs with a finite-difference derivative (differentiable once more: the
    backward pass is linear in its incoming gradient, so second derivatives are Gauss-Newton)."""

    @staticmethod
    def forward(ctx, theta, simulator, steps):
        values = theta.detach().cpu().numpy()
        ctx.batched = values.ndim == 2
        if ctx.needs_input_grad[0]:
            if ctx.batched and values.shape[0] != 1:
                raise ValueError("gradients of the simulator are taken for one vector at a time")
            out, slopes = simulator.jacobian(values.reshape(-1), steps)
            ctx.save_for_backward(torch.as_tensor(slopes, dtype=theta.dtype))
            out = out[None] if ctx.batched else out
        else:
            out = simulator.outputs(values)
            out = out if ctx.batched else out[0]
        return torch.as_tensor(out, dtype=theta.dtype)

    @staticmethod
    def backward(ctx, grad):
        # products summed elementwise rather than through BLAS: the same bits on every machine
        (slopes,) = ctx.saved_tensors
        if ctx.batched:
            return (grad[0, ..., None] * slopes).sum(dim=(0, 1, 2))[None], None, None
        return (grad[..., None] * slopes).sum(dim=(0, 1, 2)), None, None


def simulated_outputs(
    theta: torch.Tensor, simulator: WindowSimulator, steps: np.ndarray
) -> torch.Tensor:
    """X', F' of the windows at ``theta`` (``(p,)`` -> ``(W, T, 2)``; ``(B, p)`` -> ``(B, W, T,
    2)``), differentiable in ``theta`` by central differences of ``steps`` (one vector only)."""
    return _SimulatedOutputs.apply(theta, simulator, np.asarray(steps, dtype=np.float64))
