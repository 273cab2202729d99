"""Isolation after detection: residual signatures over a growing window and the fault classifier.

Once the detector has raised DD, the online diagnoser summarises what the residuals have done
since that moment, over a window that grows every second until DD falls
(`isolation_features`, running sums, O(1) per second):

``mean_rX``, ``mean_rF``
    the paper's mean residuals ``r1 = X - X_hat``, ``r2 = F - F_hat`` (normalised units);
``std_rX``, ``std_rF``
    their spread (friction and positioner faults make the stem hunt rather than shift);
``slope_rX_X``
    the least-squares slope of ``r1`` on ``X_hat`` (a stem-sensor gain fault f13 scales with the
    position; clogging f1 bites only where the stem would close past its new limit);
``slope_rF_F``, ``slope_rF_s``
    the slopes of ``r2`` on ``F_hat`` (multiplicative flow faults: sensor f19, sedimentation f2)
    and on ``s = sqrt(P1 - P2)`` (additive leak flows: bypass f18, internal leakage f6);
``dP1``, ``dP2``, ``dT1``
    the shift of the measured inputs since before the detection (f17 scales P1 or P2, f7 makes
    T1 jump), against a slow average of the fault-free past that freezes at the detection.

Slopes are shrunk towards 0 while the regressor has hardly varied (a ridge of
``SLOPE_RIDGE`` on its variance), so the first seconds give finite, small slopes.

`FaultIsolator` maps a signature to probabilities over the faults (a classifier over faults
only, by default the k-means tree of RVCs,
`~bayes_fdi.diagnosis.isolation.tree.HierarchicalClassifier`; the SVM baseline plugs in the same
way), sums them over the isolability groups found from the held-out confusion on a validation set
(`isolability_groups`, the complete-linkage rule of
`bayes_fdi.paper.reproduce.find_groups`), recalibrates the group probabilities with a
recalibrator fitted on a separate calibration set (any object with ``fit(proba, y)`` and
``transform(proba)``, e.g. `bayes_fdi.calibration.TemperatureScaler`), and scores novelty per
class (`ClassNovelty`): a signature far from every class's training signatures is an
"unknown" fault. `isolate_rows` is the compiled per-second form the online diagnoser runs:
the compiled tree's probabilities, their group sums with temperature scaling shared back to
the faults, and the novelty score, row by row.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numba import njit
from sklearn.base import clone

from bayes_fdi.diagnosis.normal_models.compiled import lean_tree_or_none, tree_proba

__all__ = [
    "ISOLATION_FEATURES",
    "SLOPE_RIDGE",
    "ClassNovelty",
    "FaultIsolator",
    "isolability_groups",
    "isolate_rows",
    "isolation_features",
    "new_feature_state",
    "novelty_score_row",
    "pairwise_confusion",
]

#: Names of the isolation features, in column order.
ISOLATION_FEATURES: tuple[str, ...] = (
    "mean_rX", "mean_rF", "std_rX", "std_rF", "slope_rX_X", "slope_rF_F", "slope_rF_s",
    "dP1", "dP2", "dT1",
)  # fmt: skip
#: Ridge added to a regressor's variance (normalised units squared) in the slopes: a slope
#: over a window in which the regressor moved by much less than sqrt(SLOPE_RIDGE) = 0.03 is
#: shrunk towards 0.
SLOPE_RIDGE = 1e-3
#: Time constant (s) of the fault-free input average the input shifts are measured against.
INPUT_REFERENCE_SECONDS = 60.0
_N_STATE = 22


def new_feature_state() -> np.ndarray:
    """A fresh state of `isolation_features` (no window open, no input reference yet)."""
    return np.zeros(_N_STATE)


@njit(cache=True, error_model="numpy")
def _features_kernel(dd, rx, rf, xh, fh, s, p1, p2, t1, alpha, ridge, st, out):  # pragma: no cover
    """Running-sum isolation features; st: [n, sums (16), ref p1 p2 t1, ref set, dd before]."""
    for t in range(dd.size):
        on = dd[t]
        if on and st[21] < 0.5:  # a new detection: open the window
            for j in range(17):
                st[j] = 0.0
        st[21] = 1.0 if on else 0.0
        if not on:
            if np.isfinite(p1[t]) and np.isfinite(p2[t]) and np.isfinite(t1[t]):
                if st[20] < 0.5:
                    st[17] = p1[t]
                    st[18] = p2[t]
                    st[19] = t1[t]
                    st[20] = 1.0
                else:
                    st[17] += alpha * (p1[t] - st[17])
                    st[18] += alpha * (p2[t] - st[18])
                    st[19] += alpha * (t1[t] - st[19])
            for j in range(out.shape[1]):
                out[t, j] = np.nan
            continue
        ok = (np.isfinite(rx[t]) and np.isfinite(rf[t]) and np.isfinite(xh[t])
              and np.isfinite(fh[t]) and np.isfinite(s[t]) and np.isfinite(p1[t])
              and np.isfinite(p2[t]) and np.isfinite(t1[t]))  # fmt: skip
        if ok:
            st[0] += 1.0
            st[1] += rx[t]
            st[2] += rf[t]
            st[3] += rx[t] * rx[t]
            st[4] += rf[t] * rf[t]
            st[5] += xh[t]
            st[6] += xh[t] * xh[t]
            st[7] += xh[t] * rx[t]
            st[8] += fh[t]
            st[9] += fh[t] * fh[t]
            st[10] += fh[t] * rf[t]
            st[11] += s[t]
            st[12] += s[t] * s[t]
            st[13] += s[t] * rf[t]
            st[14] += p1[t]
            st[15] += p2[t]
            st[16] += t1[t]
        n = st[0]
        if n < 0.5 or st[20] < 0.5:
            for j in range(out.shape[1]):
                out[t, j] = np.nan
            continue
        mx = st[1] / n
        mf = st[2] / n
        out[t, 0] = mx
        out[t, 1] = mf
        out[t, 2] = math.sqrt(max(st[3] / n - mx * mx, 0.0))
        out[t, 3] = math.sqrt(max(st[4] / n - mf * mf, 0.0))
        m = st[5] / n
        out[t, 4] = (st[7] / n - m * mx) / (max(st[6] / n - m * m, 0.0) + ridge)
        m = st[8] / n
        out[t, 5] = (st[10] / n - m * mf) / (max(st[9] / n - m * m, 0.0) + ridge)
        m = st[11] / n
        out[t, 6] = (st[13] / n - m * mf) / (max(st[12] / n - m * m, 0.0) + ridge)
        out[t, 7] = st[14] / n - st[17]
        out[t, 8] = st[15] / n - st[18]
        out[t, 9] = st[16] / n - st[19]


def isolation_features(
    dd: Any,
    r_x: Any,
    r_f: Any,
    x_hat: Any,
    f_hat: Any,
    s: Any,
    p1: Any,
    p2: Any,
    t1: Any,
    *,
    state: np.ndarray | None = None,
) -> np.ndarray:
    """The isolation features of one run, ``(n, 10)`` (NaN while DD is off).

    The window opens at each rising edge of ``dd`` and grows while it stays on; samples with
    a NaN are skipped. The input reference is an exponential average (time constant
    `INPUT_REFERENCE_SECONDS`) of P1, P2, T1 over the seconds without detection.

    Parameters
    ----------
    dd
        ``(n,)`` detection decision.
    r_x, r_f
        Raw residuals ``X - X_hat``, ``F - F_hat``.
    x_hat, f_hat, s
        Predicted position and flow, signed root of the pressure drop.
    p1, p2, t1
        Measured inputs.
    state
        State to continue from (updated in place; default a fresh one).
    """
    arrays = [np.ascontiguousarray(np.asarray(a, dtype=np.float64)) for a in
              (r_x, r_f, x_hat, f_hat, s, p1, p2, t1)]  # fmt: skip
    flags = np.ascontiguousarray(np.asarray(dd, dtype=np.bool_))
    n = flags.size
    if any(a.shape != (n,) for a in arrays):
        raise ValueError("isolation_features: every input must be a (n,) sequence")
    out = np.empty((n, len(ISOLATION_FEATURES)))
    st = new_feature_state() if state is None else state
    alpha = 1.0 / INPUT_REFERENCE_SECONDS
    _features_kernel(flags, *arrays, alpha, SLOPE_RIDGE, st, out)
    return out


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


def pairwise_confusion(y_true: Any, y_pred: Any, states: Sequence[str]) -> np.ndarray:
    """Balanced pairwise confusion ``(P(pred b | a) + P(pred a | b)) / 2`` (diagonal 0)."""
    y_true = np.asarray(y_true).astype(str)
    y_pred = np.asarray(y_pred).astype(str)
    k = len(states)
    rate = np.zeros((k, k))
    for i, a in enumerate(states):
        rows = y_true == a
        if rows.any():
            for j, b in enumerate(states):
                rate[i, j] = np.mean(y_pred[rows] == b)
    err = (rate + rate.T) / 2.0
    np.fill_diagonal(err, 0.0)
    return err


# ----------------------------------------------------------------------------------------------
# novelty per class
# ----------------------------------------------------------------------------------------------
@njit(cache=True, error_model="numpy")
def novelty_score_row(x, center, scale, protos, offsets, radius):  # pragma: no cover - compiled
    """Novelty of one row: min over classes of (distance to the nearest prototype) / radius."""
    d = x.size
    best = np.inf
    for c in range(offsets.size - 1):
        nearest = np.inf
        for i in range(offsets[c], offsets[c + 1]):
            d2 = 0.0
            for j in range(d):
                diff = (x[j] - center[j]) / scale[j] - protos[i, j]
                d2 += diff * diff
            if d2 < nearest:
                nearest = d2
        ratio = math.sqrt(nearest) / radius[c]
        if ratio < best:
            best = ratio
    return best


class ClassNovelty:
    """How unlike every class's training signatures a signature is.

    Features are standardised (training mean and std); each class keeps up to
    ``max_prototypes`` of its training rows (a seeded subset) and a radius, the ``quantile`` of
    its rows' leave-one-out nearest-neighbour distances within the class. The score of a row is
    the smallest, over classes, of its distance to the class's nearest prototype divided by the
    class radius: below 1 for about ``quantile`` of rows drawn like a class, far above 1 for a
    signature unlike every class. Infinite entries score ``inf``.

    Parameters
    ----------
    max_prototypes
        Rows kept per class (default 200).
    quantile
        Quantile of the within-class nearest-neighbour distances taken as the radius.
    random_state
        Seed of the subsets.
    """

    def __init__(
        self, *, max_prototypes: int = 200, quantile: float = 0.99, random_state: int | None = 0
    ) -> None:
        self.max_prototypes = max_prototypes
        self.quantile = quantile
        self.random_state = random_state

    def fit(self, X: Any, y: Any) -> ClassNovelty:
        """Fit on training rows ``X`` ``(n, d)`` with class labels ``y``."""
        X = np.asarray(X, dtype=np.float64)
        y = np.asarray(y).astype(str)
        if X.ndim != 2 or not np.all(np.isfinite(X)):
            raise ValueError("ClassNovelty needs finite (n, d) rows")
        rng = np.random.default_rng(self.random_state)
        self.center_ = X.mean(axis=0)
        sd = X.std(axis=0)
        self.scale_ = np.where(sd > 0, sd, 1.0)
        Z = (X - self.center_) / self.scale_
        protos, offsets, radius, classes = [], [0], [], []
        for c in np.unique(y):
            rows = np.flatnonzero(y == c)
            if rows.size > self.max_prototypes:
                rows = np.sort(rng.choice(rows, self.max_prototypes, replace=False))
            P = Z[rows]
            if P.shape[0] >= 2:
                d2 = ((P[:, None, :] - P[None, :, :]) ** 2).sum(-1)
                np.fill_diagonal(d2, np.inf)
                nn = np.sqrt(d2.min(axis=1))
                r = float(np.quantile(nn, self.quantile))
            else:
                r = 0.0
            radius.append(r if r > 0 else 1e-12)
            protos.append(P)
            offsets.append(offsets[-1] + P.shape[0])
            classes.append(str(c))
        self.classes_ = np.asarray(classes)
        self.prototypes_ = np.ascontiguousarray(np.concatenate(protos))
        self.offsets_ = np.asarray(offsets, dtype=np.int64)
        self.radius_ = np.asarray(radius, dtype=np.float64)
        return self

    def args(self) -> tuple:
        """The arrays of the compiled score."""
        return (self.center_, self.scale_, self.prototypes_, self.offsets_, self.radius_)

    def score(self, X: Any) -> np.ndarray:
        """Novelty score of each row (``inf`` for rows with an infinite entry, NaN for NaN)."""
        X = np.ascontiguousarray(np.asarray(X, dtype=np.float64))
        out = np.full(X.shape[0], np.nan)
        for i in range(X.shape[0]):
            row = X[i]
            if np.isnan(row).any():
                continue
            out[i] = np.inf if np.isinf(row).any() else novelty_score_row(row, *self.args())
        return out


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
        ``transform(proba)``; e.g. ``bayes_fdi.calibration.TemperatureScaler()``), cloned and
        fitted on the calibration set. None: no recalibration.
    group_threshold
        Pairwise held-out confusion from which two faults share a group (default 0.15, the
        threshold of the paper pipeline's 20-state analysis).
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
        The pairwise held-out confusion the groups were found from.
    """

    def __init__(
        self,
        classifier: Any = None,
        *,
        calibrator: Any = None,
        group_threshold: float = 0.15,
        random_state: int | None = 0,
    ) -> None:
        self.classifier = classifier
        self.calibrator = calibrator
        self.group_threshold = group_threshold
        self.random_state = random_state

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
        group / no recalibration)."""
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
            self.validation_confusion_ = pairwise_confusion(yv[known], pred, faults)
            # in the faults' natural order (f4 before f12), so groups read "f4|f12"
            order = sorted(range(len(faults)), key=lambda i: _natural(faults[i]))
            groups = isolability_groups([faults[i] for i in order],
                                        self.validation_confusion_[np.ix_(order, order)],
                                        threshold=self.group_threshold)  # fmt: skip
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
        if self.calibrator is not None and calibration is not None:
            Xc, yc = np.asarray(calibration[0], float), np.asarray(calibration[1]).astype(str)
            known = np.isin(yc, faults)
            gp = self.fault_proba(Xc[known]) @ self.membership_
            group_of = {f: self.group_labels_[j] for j, g in enumerate(self.groups_) for f in g}
            labels = np.array([group_of[f] for f in yc[known]])
            cal = clone(self.calibrator)
            if "classes" in cal.get_params():
                cal.set_params(classes=list(self.group_labels_))
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

    def temperature(self) -> float | None:
        """The calibrator's temperature when it is a temperature scaling (compiled path)."""
        cal = self.calibrator_
        if cal is None:
            return None
        t = getattr(cal, "temperature_", None)
        return float(t) if t is not None and not hasattr(cal, "weights_") else None


# ----------------------------------------------------------------------------------------------
# the compiled per-second isolation of the online diagnoser
# ----------------------------------------------------------------------------------------------
@njit(cache=True, error_model="numpy")
def _posterior_row(p, group_of, n_groups, temperature, floor, gp, gq, fq):  # pragma: no cover
    """Group sums of fault probabilities ``p``, temperature-scaled, shared back to faults."""
    for g in range(n_groups):
        gp[g] = 0.0
    for f in range(p.size):
        gp[group_of[f]] += p[f]
    if temperature > 0.0:
        top = -np.inf
        for g in range(n_groups):
            gq[g] = math.log(max(gp[g], floor)) / temperature
            if gq[g] > top:
                top = gq[g]
        total = 0.0
        for g in range(n_groups):
            gq[g] = math.exp(gq[g] - top)
            total += gq[g]
        for g in range(n_groups):
            gq[g] /= total
    else:
        for g in range(n_groups):
            gq[g] = gp[g]
    for f in range(p.size):
        g = group_of[f]
        fq[f] = gq[g] * p[f] / gp[g] if gp[g] > 0.0 else gq[g]


@njit(cache=True, error_model="numpy")
def isolate_rows(
    feats, tree_args_c, tree_args_o, tree_args_w, tree_args_wo, tree_args_cov, tree_args_co,
    tree_args_b, tree_args_i, tree_args_sm, tree_args_ss, moderated, paths,
    group_of, n_groups, temperature, floor, nov_c, nov_s, nov_p, nov_o, nov_r,
    phi, right, z, p, gp, out_fault, out_group, out_nov,
):  # pragma: no cover - compiled  # fmt: skip
    """Per row: tree probabilities, calibrated group/fault probabilities and novelty."""
    for t in range(feats.shape[0]):
        row = feats[t]
        ok = True
        for j in range(row.size):
            if not np.isfinite(row[j]):
                ok = False
        if not ok:
            for f in range(out_fault.shape[1]):
                out_fault[t, f] = np.nan
            for g in range(out_group.shape[1]):
                out_group[t, g] = np.nan
            out_nov[t] = np.nan
            continue
        tree_proba(row, tree_args_c, tree_args_o, tree_args_w, tree_args_wo, tree_args_cov,
                   tree_args_co, tree_args_b, tree_args_i, tree_args_sm, tree_args_ss,
                   moderated, paths, phi, right, z, p)  # fmt: skip
        _posterior_row(p, group_of, n_groups, temperature, floor, gp, out_group[t],
                       out_fault[t])  # fmt: skip
        out_nov[t] = novelty_score_row(row, nov_c, nov_s, nov_p, nov_o, nov_r)
