"""The fault isolator: fault and group probabilities of isolation signatures, with novelty.

`FaultIsolator` maps a signature (`bayes_fdi.diagnosis.isolation.signatures`) to probabilities
over the faults (a classifier over faults only, by default the k-means tree of RVCs,
`~bayes_fdi.diagnosis.isolation.tree.HierarchicalClassifier`; the SVM baseline plugs in the same
way), sums them over the isolability groups found from the held-out confusion on a validation set
(`isolability_groups`, the complete-linkage rule of
`bayes_fdi.paper.separability.find_groups`), recalibrates the group probabilities with a
recalibrator fitted on a separate calibration set (any object with ``fit(proba, y)`` and
``transform(proba)``, e.g. `bayes_fdi.calibration.TemperatureScaler`), and scores novelty per
class (`~bayes_fdi.diagnosis.isolation.class_novelty.ClassNovelty`): a signature far from every
class's training signatures is an "unknown" fault.

Online, ``run`` (a chunk of seconds) and ``update`` (one) give the per-second isolation. It keeps
no state: the memory of the stream is the signature window's. With a compiled tree
(`~bayes_fdi.diagnosis.isolation.compiled_tree.LeanTree`) or a
`~bayes_fdi.diagnosis.isolation.forest.ForestClassifier`, and a temperature scaling (one
temperature, possibly followed by the beta map of the top group of
`~bayes_fdi.calibration.TopLabelScaler`, or one per age bin of the signature,
`~bayes_fdi.calibration.AgeTemperatureScaler`, which takes each row's age) or no recalibration,
they run one compiled pass of `bayes_fdi.diagnosis.isolation.compiled_isolation`
that takes the fitted values as one named tuple: the classifier's probabilities, their group
sums recalibrated and shared back to the faults, and the novelty score, row by row.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
from sklearn.base import clone

from bayes_fdi.diagnosis.isolation.class_novelty import ClassNovelty
from bayes_fdi.diagnosis.isolation.compiled_isolation import (
    IsolationParams,
    isolate_forest_rows,
    isolate_rows,
)
from bayes_fdi.diagnosis.isolation.compiled_tree import lean_tree_or_none
from bayes_fdi.diagnosis.isolation.forest import ForestClassifier

__all__ = [
    "GROUP_RULES",
    "FaultIsolator",
    "IsolationOutput",
    "isolability_groups",
    "naming_confusion",
    "pairwise_confusion",
]


#: How the isolability groups may be found: ``"pairwise"`` (`pairwise_confusion` of the
#: signatures at fixed ages) or ``"naming"`` (`naming_confusion` of every detected second).
GROUP_RULES: tuple[str, ...] = ("pairwise", "naming")


class IsolationOutput(NamedTuple):
    """The per-second isolation of signature rows (NaN for a row without a signature)."""

    fault_proba: Any  #: ``(n, n_faults)`` calibrated fault probabilities
    group_proba: Any  #: ``(n, n_groups)`` calibrated group probabilities
    novelty: Any  #: ``(n,)`` novelty scores


# ----------------------------------------------------------------------------------------------
# groups
# ----------------------------------------------------------------------------------------------
def _natural(name: str) -> tuple[str, int]:
    """Sort key of a state name: ``f4`` before ``f12`` (letters, then the number)."""
    head = name.rstrip("0123456789")
    tail = name[len(head) :]
    return head, int(tail) if tail else -1


def isolability_groups(
    states: Sequence[str], error: Any, *, threshold: float = 0.15, linkage: str = "complete"
) -> list[list[str]]:
    """Groups of states that cannot be told apart, from a pairwise error.

    Two states are confusable when ``error[a, b] >= threshold``. With ``linkage="complete"``
    groups merge only when every pair across them is confusable, the pair of groups with the
    largest smallest error first (ties: the earliest states); with ``"single"`` (connected
    components) the largest largest error first. Groups come in order of their first state.
    `bayes_fdi.paper.separability.find_groups` uses this rule too.
    """
    e = np.asarray(error, dtype=np.float64)
    k = len(states)
    if e.shape != (k, k):
        raise ValueError(f"error must be ({k}, {k}), got {e.shape}")
    if not np.allclose(e, e.T):
        raise ValueError("error must be symmetric")
    if linkage not in ("complete", "single"):
        raise ValueError(f"linkage must be 'complete' or 'single', got {linkage!r}")
    clusters: list[list[int]] = [[i] for i in range(k)]
    while len(clusters) > 1:
        best, pair = -np.inf, None
        for a in range(len(clusters)):
            for b in range(a + 1, len(clusters)):
                block = e[np.ix_(clusters[a], clusters[b])]
                score = block.min() if linkage == "complete" else block.max()
                if score > best:
                    best, pair = score, (a, b)
        if pair is None or best < threshold:
            break
        a, b = pair
        clusters[a] = sorted(clusters[a] + clusters[b])
        del clusters[b]
    clusters.sort(key=min)
    return [[str(states[i]) for i in c] for c in clusters]


def _naming_rates(y_true: Any, y_pred: Any, states: Sequence[str]) -> np.ndarray:
    """``rate[a, b] = P(pred b | a)`` over the rows of each state."""
    y_true = np.asarray(y_true).astype(str)
    y_pred = np.asarray(y_pred).astype(str)
    k = len(states)
    rate = np.zeros((k, k))
    for i, a in enumerate(states):
        rows = y_true == a
        if rows.any():
            for j, b in enumerate(states):
                rate[i, j] = np.mean(y_pred[rows] == b)
    return rate


def pairwise_confusion(y_true: Any, y_pred: Any, states: Sequence[str]) -> np.ndarray:
    """Balanced pairwise confusion ``(P(pred b | a) + P(pred a | b)) / 2`` (diagonal 0)."""
    rate = _naming_rates(y_true, y_pred, states)
    err = (rate + rate.T) / 2.0
    np.fill_diagonal(err, 0.0)
    return err


def naming_confusion(y_true: Any, y_pred: Any, states: Sequence[str]) -> np.ndarray:
    """The larger of the two one-way confusions ``max(P(pred b | a), P(pred a | b))``
    (diagonal 0): a consistent misnaming ``a -> b`` counts in full however rarely ``b`` is
    named ``a``, where the balanced `pairwise_confusion` halves it."""
    rate = _naming_rates(y_true, y_pred, states)
    err = np.maximum(rate, rate.T)
    np.fill_diagonal(err, 0.0)
    return err


# ----------------------------------------------------------------------------------------------
# the isolator
# ----------------------------------------------------------------------------------------------
class FaultIsolator:
    """Fault and group probabilities of isolation signatures, with novelty.

    Parameters
    ----------
    classifier
        Unfitted probabilistic classifier over the faults (``fit``, ``predict_proba``,
        ``classes_``); cloned. None: the k-means tree of RVCs
        (``HierarchicalClassifier(RVC(kernel="rbf", width=2.0))``).
    calibrator
        Unfitted recalibrator of the group probabilities (``fit(proba, y)``,
        ``transform(proba)``; e.g. ``bayes_fdi.calibration.TemperatureScaler()``, or one whose
        ``uses_ages`` is true and whose ``fit`` and ``transform`` also take the rows' ages,
        ``bayes_fdi.calibration.AgeTemperatureScaler()``), cloned and fitted on the calibration
        set. None: no recalibration. Not fitted when every known fault falls into one group
        (its probability is 1).
    group_threshold
        Held-out confusion from which two faults (or groups) share a group (default 0.15, the
        threshold of the paper pipeline's 20-state analysis).
    group_rule
        How the validation set's confusion makes the groups: ``"pairwise"`` (default, the
        paper's): the balanced pairwise confusion of two faults (`pairwise_confusion`);
        ``"naming"``: the larger one-way confusion (`naming_confusion`), which merges a
        consistent misnaming of one fault as another. Both with complete linkage
        (`isolability_groups`).
    random_state
        Seed of the tree design and of the novelty subsets.

    Attributes
    ----------
    faults_ : numpy.ndarray
        Fault names, columns of the fault probabilities.
    groups_ : tuple of tuple of str
    group_labels_ : tuple of str
        ``"|"``-joined members.
    membership_ : numpy.ndarray
        ``(n_faults, n_groups)`` 0/1.
    classifier_, calibrator_, novelty_ : fitted parts
    lean_ : LeanTree or None
        Compiled form of the classifier when it allows one.
    validation_confusion_ : numpy.ndarray
        The pairwise held-out confusion the groups were found from (`pairwise_confusion` or
        `naming_confusion`, by ``group_rule``).
    group_of_ : numpy.ndarray
        ``(n_faults,)`` int64: the group (column of the group probabilities) of each fault.
    """

    def __init__(
        self,
        classifier: Any = None,
        *,
        calibrator: Any = None,
        group_threshold: float = 0.15,
        group_rule: str = "pairwise",
        random_state: int | None = 0,
    ) -> None:
        self.classifier = classifier
        self.calibrator = calibrator
        self.group_threshold = group_threshold
        self.group_rule = group_rule
        self.random_state = random_state

    @classmethod
    def upgrade_model_file(cls, data: dict, format_version: int) -> dict:
        """An isolator saved before format 10 found its groups by the pairwise rule."""
        return {"group_rule": "pairwise", **data}

    def _make_classifier(self) -> Any:
        if self.classifier is not None:
            return clone(self.classifier)
        from bayes_fdi.diagnosis.isolation.tree import HierarchicalClassifier
        from bayes_fdi.rvm import RVC

        return HierarchicalClassifier(RVC(kernel="rbf", width=2.0), random_state=self.random_state)

    def fit(
        self,
        X: Any,
        y: Any,
        *,
        validation: tuple[Any, Any] | None = None,
        calibration: tuple[Any, Any] | None = None,
    ) -> FaultIsolator:
        """Fit the classifier on ``(X, y)``, the groups on ``validation``, the calibrator on
        ``calibration`` (each a ``(rows, labels)`` pair; without one, every fault is its own
        group / no recalibration). A calibrator that takes ages
        (`~bayes_fdi.calibration.AgeTemperatureScaler`) needs ``calibration=(rows, labels,
        ages)``, the ages being the seconds each row's signature has grown."""
        if self.group_rule not in GROUP_RULES:
            raise ValueError(
                f"group_rule must be one of {', '.join(GROUP_RULES)}, got {self.group_rule!r}"
            )
        X = np.asarray(X, dtype=np.float64)
        y = np.asarray(y).astype(str)
        if np.unique(y).size < 2:
            raise ValueError("FaultIsolator needs signatures of at least two faults")
        self.classifier_ = self._make_classifier().fit(X, y)
        self.faults_ = np.asarray(self.classifier_.classes_).astype(str)
        self.lean_ = lean_tree_or_none(self.classifier_)
        self.novelty_ = ClassNovelty(random_state=self.random_state).fit(X, y)
        faults = list(self.faults_)
        if validation is not None:
            Xv, yv = np.asarray(validation[0], float), np.asarray(validation[1]).astype(str)
            known = np.isin(yv, faults)
            pred = self.faults_[np.argmax(self.fault_proba(Xv[known]), axis=1)]
            confusion = naming_confusion if self.group_rule == "naming" else pairwise_confusion
            self.validation_confusion_ = confusion(yv[known], pred, faults)
            # in the faults' natural order (f4 before f12), so groups read "f4|f12"
            order = sorted(range(len(faults)), key=lambda i: _natural(faults[i]))
            groups = isolability_groups(
                [faults[i] for i in order],
                self.validation_confusion_[np.ix_(order, order)],
                threshold=self.group_threshold,
            )
        else:
            self.validation_confusion_ = np.zeros((len(faults), len(faults)))
            groups = [[f] for f in sorted(faults, key=_natural)]
        self.groups_ = tuple(tuple(g) for g in groups)
        self.group_labels_ = tuple("|".join(g) for g in self.groups_)
        self.membership_ = np.zeros((len(faults), len(groups)))
        for j, g in enumerate(self.groups_):
            for f in g:
                self.membership_[faults.index(f), j] = 1.0
        self.calibrator_ = None
        # one group (every known fault confused with every other) has probability 1: nothing
        # to calibrate
        if self.calibrator is not None and calibration is not None and len(self.groups_) > 1:
            Xc, yc = np.asarray(calibration[0], float), np.asarray(calibration[1]).astype(str)
            known = np.isin(yc, faults)
            gp = self.summed_groups(self.fault_proba(Xc[known]))
            group_of = {f: self.group_labels_[j] for j, g in enumerate(self.groups_) for f in g}
            labels = np.array([group_of[f] for f in yc[known]])
            cal = clone(self.calibrator)
            if "classes" in cal.get_params():
                cal.set_params(classes=list(self.group_labels_))
            if _uses_ages(cal):
                if len(calibration) < 3:
                    raise ValueError(
                        f"{type(cal).__name__} needs the calibration rows' ages: pass "
                        "calibration=(rows, labels, ages)"
                    )
                self.calibrator_ = cal.fit(gp, labels, np.asarray(calibration[2])[known])
            else:
                self.calibrator_ = cal.fit(gp, labels)
        return self

    # ------------------------------------------------------------------ prediction
    def fault_proba(self, X: Any) -> np.ndarray:
        """Uncalibrated fault probabilities ``(n, n_faults)`` (compiled tree when available)."""
        X = np.ascontiguousarray(np.asarray(X, dtype=np.float64))
        if self.lean_ is not None:
            return self.lean_.predict_proba(X)
        if X.shape[0] == 0:
            return np.empty((0, self.faults_.size))
        return np.asarray(self.classifier_.predict_proba(X), dtype=np.float64)

    def summed_groups(self, fault_proba: np.ndarray) -> np.ndarray:
        """Uncalibrated group probabilities ``(n, n_groups)``: each group's faults summed.

        A sum of probabilities that add up to 1 can exceed 1 by rounding (a forest that names
        one group unanimously, its leaf shares averaged over the trees): the sums are held in
        [0, 1], which moves them by a few units in the last place at most.
        """
        return np.clip(fault_proba @ self.membership_, 0.0, 1.0)

    def temperature(self) -> float | None:
        """The calibrator's temperature when it is a temperature scaling (compiled path)."""
        cal = self.calibrator_
        if cal is None:
            return None
        t = getattr(cal, "temperature_", None)
        return float(t) if t is not None and not hasattr(cal, "weights_") else None

    def temperatures(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The calibrator's temperatures and the upper edges of their age bins (``(1,)`` and
        ``(0,)`` for one temperature scaling; an `~bayes_fdi.calibration.AgeTemperatureScaler`'s
        bins), or None when the calibrator is not a temperature scaling (or there is none)."""
        T = self.temperature()
        if T is not None:
            return np.array([T]), np.zeros(0)
        cal = self.calibrator_
        temps = getattr(cal, "temperatures_", None)
        if temps is None or not _uses_ages(cal):
            return None
        return (
            np.ascontiguousarray(temps, dtype=np.float64),
            np.ascontiguousarray(cal.edges_, dtype=np.float64),
        )

    def top_map(self) -> np.ndarray:
        """The calibrator's beta map of the top group after its temperature (``(3,)``, a
        `~bayes_fdi.calibration.TopLabelScaler`), or an empty array."""
        coef = getattr(self.calibrator_, "top_map_", None)
        return np.zeros(0) if coef is None else np.ascontiguousarray(coef, dtype=np.float64)

    def _compiled_rows(self) -> tuple[Any, Any] | None:
        """The compiled path's classifier arrays and the row loop that takes them, or None: a
        compiled tree or a `ForestClassifier`, with no calibrator, a temperature scaling (one or
        one per age bin) or a top-label scaling."""
        if self.calibrator_ is not None and self.temperatures() is None:
            return None
        if self.lean_ is not None:
            return self.lean_.arrays(), isolate_rows
        if isinstance(self.classifier_, ForestClassifier):
            return self.classifier_.arrays(), isolate_forest_rows
        return None

    @property
    def rows_independent(self) -> bool:
        """Whether `run` gives each row the numbers it gives that row alone (the compiled
        path, `_compiled_rows`)."""
        return self._compiled_rows() is not None

    @property
    def group_of_(self) -> np.ndarray:
        """``(n_faults,)`` int64: the group of each fault."""
        return np.ascontiguousarray(np.argmax(self.membership_, axis=1).astype(np.int64))

    # ------------------------------------------------------------------ online
    @property
    def uses_ages(self) -> bool:
        """Whether the calibrated probabilities depend on the signatures' ages (`run`'s
        ``ages``)."""
        return getattr(self, "calibrator_", None) is not None and _uses_ages(self.calibrator_)

    def run(self, features: Any, ages: Any = None) -> IsolationOutput:
        """Fault and group probabilities and novelty of signature rows, row by row.

        The per-second isolation of the online diagnoser: the classifier's fault
        probabilities, summed over the groups and recalibrated, shared back to the faults in
        proportion, and the novelty score. With a compiled tree (``lean_``) or a forest and no
        calibrator, a temperature scaling (one, or one per age bin) or a top-label scaling, one
        compiled pass whose every row's result is independent of the others; otherwise through
        the classifier's and calibrator's own ``predict_proba`` and ``transform`` (batched:
        rounding may depend on the rows around). A row with a NaN (no signature) gives NaN.

        Parameters
        ----------
        features
            ``(n, n_features)`` signatures.
        ages
            ``(n,)`` seconds each signature has grown (the signature window's complete
            seconds); needed when the calibration depends on them (`uses_ages`), else ignored.

        Returns
        -------
        IsolationOutput
            ``fault_proba`` ``(n, n_faults)``, ``group_proba`` ``(n, n_groups)``, ``novelty``
            ``(n,)``.
        """
        feats = np.ascontiguousarray(np.asarray(features, dtype=np.float64))
        if feats.ndim != 2:
            raise ValueError(f"features must be (n, n_features), got shape {feats.shape}")
        n = feats.shape[0]
        ages = self._ages(ages, n)
        n_f, n_g = self.faults_.size, len(self.groups_)
        fq, gq, nov = np.empty((n, n_f)), np.empty((n, n_g)), np.empty(n)
        compiled = self._compiled_rows()
        if compiled is not None:
            floor = float(getattr(self.calibrator_, "floor", 1e-12))
            temps, edges = self.temperatures() or (np.zeros(0), np.zeros(0))
            arrays, isolate = compiled
            params = IsolationParams(
                classifier=arrays,
                group_of=self.group_of_,
                n_groups=n_g,
                temperatures=temps,
                age_edges=edges,
                floor=floor,
                top_map=self.top_map(),
                novelty=self.novelty_.arrays(),
            )
            isolate(feats, ages, params, fq, gq, nov)
            return IsolationOutput(fq, gq, nov)
        fq[:], gq[:], nov[:] = np.nan, np.nan, np.nan
        ok = np.all(np.isfinite(feats), axis=1)
        if ok.any():
            group_of = self.group_of_
            p = self.fault_proba(feats[ok])
            gp = self.summed_groups(p)
            if self.calibrator_ is None:
                g = gp
            elif self.uses_ages:
                g = self.calibrator_.transform(gp, ages[ok])
            else:
                g = self.calibrator_.transform(gp)
            with np.errstate(invalid="ignore", divide="ignore"):
                share = np.where(gp[:, group_of] > 0, p / gp[:, group_of], 1.0)
            gq[ok] = g
            fq[ok] = g[:, group_of] * share
            nov[ok] = self.novelty_.score(feats[ok])
        return IsolationOutput(fq, gq, nov)

    def _ages(self, ages: Any, n: int) -> np.ndarray:
        """``ages`` as ``(n,)`` float64, checked; zeros where the calibration does not use
        them and none are given."""
        if ages is None:
            if self.uses_ages:
                raise ValueError(
                    "this isolator's calibration depends on the signatures' ages: pass ages "
                    "(the seconds each signature has grown)"
                )
            return np.zeros(n)
        a = np.ascontiguousarray(np.asarray(ages, dtype=np.float64).reshape(-1))
        if a.size != n:
            raise ValueError(f"ages must have one value per row ({n}), got {a.size}")
        if not np.all(np.isfinite(a) & (a >= 0)):
            raise ValueError("ages must be finite and >= 0 (seconds)")
        return a

    def update(self, features: Any, age: float | None = None) -> IsolationOutput:
        """`run` on one signature ``(n_features,)`` of ``age`` seconds: ``(n_faults,)``,
        ``(n_groups,)``, a float."""
        ages = None if age is None else [age]
        out = self.run(np.asarray(features, dtype=np.float64).reshape(1, -1), ages)
        return IsolationOutput(out.fault_proba[0], out.group_proba[0], float(out.novelty[0]))


def _uses_ages(calibrator: Any) -> bool:
    """Whether a recalibrator's ``fit`` and ``transform`` take the rows' ages."""
    return bool(getattr(calibrator, "uses_ages", False))
