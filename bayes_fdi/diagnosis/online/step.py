"""One step of the online diagnoser's stream: consecutive seconds of one run through its
components.

`OnlineDiagnoser` (`bayes_fdi.diagnosis.online.diagnoser`) hands its fitted components to
`step` as one named tuple (`Components`) with the run's state (`RunState`) and gets back every
per-second quantity and the state after the last second; the state passed in is never changed.
Per second: the normal models' predictions, the standardised residuals and their whitened
innovations, the sequential tests and the detection decision DD, the isolation signature since
the detection and its fault and group probabilities with novelty, the input envelope's checks
and the fit proof. `step_runs` advances many runs at once (each component's ``run_stacked``);
`step` is `step_runs` of one run. ``run`` over a recording and ``update`` for one second both
go through `step_runs`, so they give the same numbers.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, NamedTuple

import numpy as np

from bayes_fdi.diagnosis.component_state import as_stack_of_one
from bayes_fdi.diagnosis.detection.decision import DetectionDecision
from bayes_fdi.diagnosis.isolation.isolator import FaultIsolator
from bayes_fdi.diagnosis.isolation.signatures import SignatureInputs, SignatureWindow
from bayes_fdi.diagnosis.normal_models.dynamic import standardised_residuals
from bayes_fdi.diagnosis.normal_models.dynamic_kernel import signed_root
from bayes_fdi.diagnosis.online.change_point import change_ages
from bayes_fdi.diagnosis.online.envelope import ENVELOPE_CHANNELS, InputEnvelope
from bayes_fdi.diagnosis.online.fit_proof import FitProof
from bayes_fdi.diagnosis.online.state import PerOutput, RunState, StreamState
from bayes_fdi.diagnosis.online.stream import MODEL_OUTPUTS

__all__ = ["Components", "check_stream_state", "init_run_state", "step", "step_runs"]


class Components(NamedTuple):
    """The fitted online components of a diagnoser, in the order a second goes through them."""

    normal_models: Any  #: `DynamicNormalModels` (or a model with its stream interface)
    whiteners: PerOutput  #: `ARWhitener` of X and F
    detector: Any  #: `CUSUM` or `GLR`, one per output (the same parameters)
    decision: DetectionDecision
    signature: SignatureWindow
    envelope: InputEnvelope
    fit_proof: FitProof
    isolator: FaultIsolator | None  #: None: detection only


def init_run_state(components: Components) -> RunState:
    """A fresh stream state of one run."""
    return RunState(
        models=components.normal_models.init_state(),
        whiten=PerOutput(*(w.init_state() for w in components.whiteners)),
        detect=PerOutput(components.detector.init_state(), components.detector.init_state()),
        decision=components.decision.init_state(),
        signature=components.signature.init_state(),
        onset=components.envelope.init_state(),
        proof=components.fit_proof.init_state(),
        seconds=0,
    )


def check_stream_state(components: Components, state: Any, n_runs: int) -> None:
    """Raise a `ValueError` unless ``state`` is a `StreamState` of ``n_runs`` runs of these
    components (naming the field that does not fit)."""
    if not isinstance(state, StreamState):
        raise ValueError(
            f"state must be the StreamState returned by run(..., return_state=True), got "
            f"{type(state).__name__}"
        )
    state.check_layout()
    if state.n_runs != n_runs:
        raise ValueError(f"state is of {state.n_runs} run(s), the recording has {n_runs}")
    one = state.run(0)
    components.normal_models.check_state(one.models)
    for whitener, whiten in zip(components.whiteners, one.whiten, strict=True):
        whitener.check_state(whiten)
    for detect in one.detect:
        components.detector.check_state(detect)
    components.decision.check_state(one.decision)
    components.signature.check_state(one.signature)
    components.envelope.check_state(one.onset)
    components.fit_proof.check_state(one.proof)


def _isolate(
    isolator: FaultIsolator | None, feats: np.ndarray, ages: np.ndarray
) -> dict[str, np.ndarray]:
    """Fault/group probabilities and novelty of ``(runs, n, 10)`` signatures ``(runs, n)``
    seconds old (NaN rows stay NaN): every row at once where the rows are independent, else one
    call per run (the rows of one run together, as `run` of one run)."""
    shape = feats.shape[:2]
    if isolator is None:
        return {
            "fault_proba": np.full((*shape, 0), np.nan),
            "group_proba": np.full((*shape, 0), np.nan),
            "novelty": np.full(shape, np.nan),
        }
    if isolator.rows_independent:
        out = isolator.run(feats.reshape(-1, feats.shape[2]), ages.reshape(-1))
        return {k: v.reshape(*shape, *v.shape[1:]) for k, v in out._asdict().items()}
    per_run = [isolator.run(f, a)._asdict() for f, a in zip(feats, ages, strict=True)]
    return {k: np.stack([o[k] for o in per_run]) for k in per_run[0]}


def step_runs(
    components: Components, channels: Mapping[str, np.ndarray], state: StreamState
) -> tuple[dict[str, Any], StreamState]:
    """Every per-second quantity of consecutive seconds of many runs, and the state after them.

    Each component advances every run at once (its ``run_stacked``: one compiled loop over the
    runs, each run through the kernel of its ``run``), so each run's numbers equal those of
    `step` on that run alone.

    Parameters
    ----------
    components
        The fitted components.
    channels
        ``(runs, n)`` float64 arrays of CV, P1, P2, T1, X, F (NaN = missing).
    state
        The runs' `StreamState` after the preceding second (not changed; checked by the
        components).

    Returns
    -------
    quantities : dict
        ``(runs, n)`` arrays ``X_hat``, ``X_hat_std``, ``F_hat``, ``F_hat_std``, ``r_X``,
        ``r_F`` (innovations), ``stat_X``, ``stat_F``, ``DD``, ``novel_inputs``,
        ``novel_onset``, ``unproven_onset``, ``novelty``, ``window_seconds`` (the complete
        seconds of the signature window, its age); ``features`` ``(runs, n, 10)``,
        ``fault_proba`` ``(runs, n, n_faults)``, ``group_proba`` ``(runs, n, n_groups)``.
    state : StreamState
        Read-only.
    """
    c = {k: np.ascontiguousarray(np.asarray(v, dtype=np.float64)) for k, v in channels.items()}
    pred, models_state = components.normal_models.run_stacked(c, state.models)
    out: dict[str, Any] = {k: pred[:, :, j] for j, k in enumerate(MODEL_OUTPUTS)}
    r_x, z_x = standardised_residuals(c["X"], pred[:, :, 0], pred[:, :, 1])
    r_f, z_f = standardised_residuals(c["F"], pred[:, :, 2], pred[:, :, 3])
    e_x, whiten_x = components.whiteners.X.run_stacked(z_x, state.whiten.X)
    e_f, whiten_f = components.whiteners.F.run_stacked(z_f, state.whiten.F)
    test_x, detect_x = components.detector.run_stacked(e_x, state.detect.X)
    test_f, detect_f = components.detector.run_stacked(e_f, state.detect.F)
    out["r_X"], out["r_F"] = e_x, e_f
    out["stat_X"], out["stat_F"] = test_x.statistic, test_f.statistic
    stats = np.stack([test_x.statistic, test_f.statistic], axis=-1)
    dd, decision = components.decision.run_stacked(stats, state.decision)
    out["DD"] = dd
    p1, p2, t1 = c["P1"], c["P2"], c["T1"]
    window = SignatureInputs(
        dd, r_x, r_f, pred[:, :, 0], pred[:, :, 2], signed_root(p1, p2), p1, p2, t1
    )
    out["window_seconds"] = np.empty(dd.shape)
    out["features"], signature = components.signature.run_stacked(
        window, state.signature, seconds=out["window_seconds"]
    )
    inputs = np.stack([c[k] for k in ENVELOPE_CHANNELS], axis=-1)
    novel_levels = components.envelope.outside(inputs.reshape(-1, 4)).reshape(dd.shape)
    since = np.stack([test_x.since, test_f.since], axis=-1)
    decision_levels = (components.decision.threshold, components.decision.clear)
    ages, excursion = change_ages(stats, since, *decision_levels, state.onset.excursion)
    out["novel_onset"], fast, onset = components.envelope.run_stacked_flags(
        inputs, dd, state.onset, ages
    )
    onset = onset._replace(excursion=excursion)
    out["novel_inputs"] = novel_levels | fast
    measured = np.isfinite(inputs).all(axis=-1) & np.isfinite(c["X"]) & np.isfinite(c["F"])
    out["unproven_onset"], proof = components.fit_proof.run_stacked(
        dd, measured & ~out["novel_inputs"], state.proof, ages
    )
    out.update(_isolate(components.isolator, out["features"], out["window_seconds"]))
    end = StreamState(
        models=models_state,
        whiten=PerOutput(whiten_x, whiten_f),
        detect=PerOutput(detect_x, detect_f),
        decision=decision,
        signature=signature,
        onset=onset,
        proof=proof,
        seconds=np.asarray(state.seconds, dtype=np.int64) + dd.shape[1],
    )
    for array in end.arrays().values():
        array.flags.writeable = False
    return out, end


def step(
    components: Components, channels: Mapping[str, np.ndarray], state: RunState
) -> tuple[dict[str, Any], RunState]:
    """Every per-second quantity of consecutive seconds of one run, and the state after them:
    `step_runs` of that run alone.

    Parameters
    ----------
    components
        The fitted components.
    channels
        ``(n,)`` float64 arrays of CV, P1, P2, T1, X, F (NaN = missing).
    state
        The run's state after the preceding second (not changed).

    Returns
    -------
    quantities : dict
        The arrays of `step_runs` of the run: ``(n,)``, ``features`` ``(n, 10)``,
        ``fault_proba`` ``(n, n_faults)``, ``group_proba`` ``(n, n_groups)``.
    state : RunState
    """
    rows = {k: np.asarray(v, dtype=np.float64)[None] for k, v in channels.items()}
    fields = [as_stack_of_one(component_state) for component_state in state[:-1]]
    stacked = StreamState(*fields, np.array([state.seconds], dtype=np.int64))
    out, end = step_runs(components, rows, stacked)
    return {k: v[0] for k, v in out.items()}, end.run(0)
