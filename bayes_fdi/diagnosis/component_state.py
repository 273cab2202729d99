"""The state of an online component: a named tuple of numpy arrays, checked, copied and stacked
the same way by every component.

Each online component of `bayes_fdi.diagnosis` (the dynamic normal models' predictor, the AR
whitener, the sequential detectors, the detection decision, the isolation signature window, the
input envelope) keeps what one second needs of the seconds before it in a named tuple of
arrays. The component creates it (``init_state``), checks it (``check_state``, with these
functions) and returns a new one from every ``update`` and ``run``: its compiled kernel works on
a `writable_copy`, so a state once handed out never changes. The online diagnoser nests the
components' states and stacks those of several runs along a leading ``run`` axis
(`stack_states`, read-only; `state_of_run` takes one run's back out); a component's
``run_stacked`` advances such a stacked state of many runs in one compiled call
(`check_stacked_state` checks it).

Written by hand: a few lines over numpy that no library offers for named tuples.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, TypeVar

import numpy as np

__all__ = [
    "as_stack_of_one",
    "check_stacked_state",
    "check_state",
    "one_sequence",
    "stack_states",
    "stacked_sequences",
    "state_of_run",
    "working_state",
    "writable_copy",
]

State = TypeVar("State", bound=tuple)


def _is_state(value: Any) -> bool:
    return isinstance(value, tuple) and hasattr(value, "_fields")


def check_state(state: Any, fresh: tuple, what: str) -> None:
    """Raise a `ValueError` naming the field unless ``state`` is laid out like ``fresh``.

    ``state`` must be of the class of ``fresh`` (a named tuple), and each field an array of the
    same dtype and shape as ``fresh``'s (named tuples nested in it checked alike). ``what``
    names the state in the message (e.g. ``"whitener state"``).
    """
    cls = type(fresh)
    if type(state) is not cls:
        raise ValueError(f"{what} must be a {cls.__name__}, got {type(state).__name__}")
    for name, want, got in zip(cls._fields, fresh, state, strict=True):
        if type(got) is np.ndarray and got.shape == want.shape and got.dtype == want.dtype:
            continue  # the usual case, first
        if _is_state(want):
            check_state(got, want, f"{what}.{name}")
        elif not isinstance(got, np.ndarray):
            raise ValueError(f"{what}.{name} must be an array, got {type(got).__name__}")
        else:
            raise ValueError(
                f"{what}.{name} must be a {want.dtype} array of shape {want.shape}, got "
                f"{got.dtype} {got.shape} (the state of another model?)"
            )


def check_stacked_state(state: Any, fresh: tuple, n_runs: int, what: str) -> None:
    """Raise a `ValueError` naming the field unless ``state`` stacks ``n_runs`` states laid out
    like ``fresh`` (each field an array of ``fresh``'s dtype and shape after a leading axis of
    ``n_runs``, as `stack_states` makes them)."""
    cls = type(fresh)
    if type(state) is not cls:
        raise ValueError(f"{what} must be a {cls.__name__}, got {type(state).__name__}")
    for name, want, got in zip(cls._fields, fresh, state, strict=True):
        if _is_state(want):
            check_stacked_state(got, want, n_runs, f"{what}.{name}")
            continue
        shape = (n_runs, *want.shape)
        if not isinstance(got, np.ndarray):
            raise ValueError(f"{what}.{name} must be an array, got {type(got).__name__}")
        if got.shape != shape or got.dtype != want.dtype:
            raise ValueError(
                f"{what}.{name} must be a {want.dtype} array of shape {shape} ({n_runs} "
                f"run(s)), got {got.dtype} {got.shape}"
            )


def stacked_sequences(values: Any, state: State, fresh: tuple, what: str) -> tuple[Any, State]:
    """The start of a component's ``run_stacked``: ``values`` as a contiguous float64
    ``(runs, n)`` array (a `ValueError` for another shape), and a writable copy of ``state``
    once it is checked to stack one state laid out like ``fresh`` per run."""
    x = np.ascontiguousarray(np.asarray(values, dtype=np.float64))
    if x.ndim != 2:
        raise ValueError(f"expected (runs, n) sequences, got shape {x.shape}")
    check_stacked_state(state, fresh, x.shape[0], what)
    return x, writable_copy(state)


def writable_copy(state: State) -> State:
    """A copy of ``state`` whose arrays a compiled kernel may update in place."""
    return type(state)(*(v.copy() if type(v) is np.ndarray else writable_copy(v) for v in state))


def working_state(component: Any, state: Any) -> Any:
    """The state a component's ``run`` starts from: its fresh state when ``state`` is None,
    else a checked writable copy (the caller's state is never changed)."""
    if state is None:
        return component.init_state()
    component.check_state(state)
    return writable_copy(state)


def one_sequence(values: Any) -> np.ndarray:
    """``values`` as a contiguous float64 1-D array (a `ValueError` for another shape)."""
    x = np.ascontiguousarray(np.asarray(values, dtype=np.float64))
    if x.ndim != 1:
        raise ValueError(f"expected one sequence (1-D), got shape {x.shape}")
    return x


def stack_states(states: Sequence[State]) -> State:
    """One state whose arrays stack those of ``states`` along a new leading axis (read-only)."""
    if not states:
        raise ValueError("no states to stack")
    first = states[0]
    fields = []
    for k, value in enumerate(first):
        parts = [s[k] for s in states]
        if _is_state(value):
            fields.append(stack_states(parts))
        else:
            stacked = np.stack([np.asarray(p) for p in parts])
            stacked.flags.writeable = False
            fields.append(stacked)
    return type(first)(*fields)


def as_stack_of_one(state: State) -> State:
    """``state`` as a stack of one run: views of its arrays with a leading axis of 1."""
    return type(state)(*(as_stack_of_one(v) if _is_state(v) else v[None] for v in state))


def state_of_run(stacked: State, i: int) -> State:
    """Row ``i`` of a state made by `stack_states` (read-only views)."""
    return type(stacked)(*(state_of_run(v, i) if _is_state(v) else v[i] for v in stacked))
