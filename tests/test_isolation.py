"""Isolation signatures, groups, novelty and the fault isolator (bayes_fdi.diagnosis.isolation:
signatures, isolator, class_novelty), and the compiled predictors they use (compiled_tree,
bayes_fdi.diagnosis.normal_models.compiled)."""

from __future__ import annotations

import numpy as np
import pytest

from bayes_fdi.diagnosis.isolation.class_novelty import ClassNovelty
from bayes_fdi.diagnosis.isolation.compiled_tree import LeanTree
from bayes_fdi.diagnosis.isolation.isolator import (
    FaultIsolator,
    isolability_groups,
    pairwise_confusion,
)
from bayes_fdi.diagnosis.isolation.signatures import (
    INPUT_REFERENCE_SECONDS,
    ISOLATION_FEATURES,
    SLOPE_RIDGE,
    SignatureInputs,
    SignatureState,
    SignatureWindow,
)
from bayes_fdi.diagnosis.isolation.tree import HierarchicalClassifier
from bayes_fdi.diagnosis.normal_models.compiled import LeanRVR
from bayes_fdi.rvm import RVC, RVR


def _reference_features(t, start, cols, ref):
    """The features at second t of a window opened at `start`, by direct numpy."""
    rx, rf, xh, fh, s, p1, p2, t1 = (c[start : t + 1] for c in cols)

    def slope(x, y):
        return np.mean((x - x.mean()) * (y - y.mean())) / (np.var(x) + SLOPE_RIDGE)

    return np.array([
        rx.mean(), rf.mean(), rx.std(), rf.std(), slope(xh, rx), slope(fh, rf), slope(s, rf),
        p1.mean() - ref[0], p2.mean() - ref[1], t1.mean() - ref[2],
    ])  # fmt: skip


def test_features_equal_direct_window_statistics(rng):
    n = 400
    cols = [rng.normal(size=n) * 0.01 for _ in range(2)] + [
        rng.uniform(0.2, 0.8, n), rng.uniform(0.2, 1.0, n), rng.uniform(0.4, 0.5, n),
        0.87 + 0.01 * rng.normal(size=n), 0.65 + 0.01 * rng.normal(size=n),
        0.22 + 0.001 * rng.normal(size=n),
    ]  # fmt: skip
    dd = np.zeros(n, dtype=bool)
    dd[150:260] = True
    dd[300:330] = True
    window = SignatureWindow()
    feats, _ = window.run(SignatureInputs(dd, *cols))
    assert feats.shape == (n, len(ISOLATION_FEATURES))
    assert np.isnan(feats[~dd]).all() and np.isfinite(feats[dd]).all()
    # the input reference: an exponential average over the seconds without detection
    alpha = 1.0 / INPUT_REFERENCE_SECONDS
    ref = np.array([cols[5][0], cols[6][0], cols[7][0]])
    for t in range(1, 150):
        ref += alpha * (np.array([cols[5][t], cols[6][t], cols[7][t]]) - ref)
    for t in (150, 151, 200, 259):
        # running sums against two-pass statistics: rounding of ~100-term sums of O(1) values
        np.testing.assert_allclose(feats[t], _reference_features(t, 150, cols, ref),
                                   rtol=1e-9, atol=1e-12)  # fmt: skip
    # a new detection opens a new window (the reference moved on between the two)
    for t in range(260, 300):
        ref += alpha * (np.array([cols[5][t], cols[6][t], cols[7][t]]) - ref)
    np.testing.assert_allclose(feats[320], _reference_features(320, 300, cols, ref),
                               rtol=1e-9, atol=1e-12)  # fmt: skip
    # continuing from a carried state equals processing the whole run, second by second too
    first, state = window.run(SignatureInputs(dd[:200], *(c[:200] for c in cols)))
    second, _ = window.run(SignatureInputs(dd[200:], *(c[200:] for c in cols)), state)
    np.testing.assert_array_equal(np.vstack([first, second]), feats)
    state, rows = window.init_state(), []
    for t in range(n):
        row, state = window.update(SignatureInputs(dd[t], *(c[t] for c in cols)), state)
        rows.append(row)
    np.testing.assert_array_equal(np.array(rows), feats)


def test_signature_state_is_checked_by_field():
    window = SignatureWindow()
    fresh = window.init_state()
    with pytest.raises(ValueError, match=r"signature state.sums must be a float64 array"):
        window.check_state(fresh._replace(sums=np.zeros(15)))
    with pytest.raises(ValueError, match="reference_set must be a bool array"):
        window.check_state(fresh._replace(reference_set=np.zeros(1)))
    with pytest.raises(ValueError, match="must be a SignatureState"):
        window.check_state(tuple(fresh))
    assert isinstance(fresh, SignatureState)


def test_groups_equal_the_paper_pipelines_find_groups(rng):
    from bayes_fdi.paper.separability import find_groups

    states = [f"f{i}" for i in range(1, 9)]
    for _ in range(20):
        a = rng.uniform(0, 0.3, (8, 8))
        err = (a + a.T) / 2
        np.fill_diagonal(err, 0.0)
        assert isolability_groups(states, err, threshold=0.15) == find_groups(
            states, err, threshold=0.15
        )


def test_pairwise_confusion_is_balanced():
    y = np.array(["a"] * 4 + ["b"] * 2)
    p = np.array(["a", "a", "b", "b", "b", "a"])
    err = pairwise_confusion(y, p, ["a", "b"])
    # P(b | a) = 2/4, P(a | b) = 1/2 -> (0.5 + 0.5) / 2
    np.testing.assert_allclose(err, [[0.0, 0.5], [0.5, 0.0]])


def test_class_novelty_flags_a_far_signature(rng):
    X = np.vstack([rng.normal(0, 1, (150, 3)), rng.normal(6, 1, (150, 3))])
    y = np.repeat(["f1", "f2"], 150)
    nov = ClassNovelty().fit(X, y)
    inside = nov.score(np.vstack([rng.normal(0, 1, (300, 3)), rng.normal(6, 1, (300, 3))]))
    # the radius is the 99 % quantile of within-class nearest-neighbour distances among the
    # kept prototypes; new draws from the classes mostly fall inside it
    assert np.mean(inside > 1.5) < 0.05
    far = nov.score(np.array([[30.0, -30.0, 30.0], [np.inf, 0.0, 0.0], [np.nan, 0.0, 0.0]]))
    assert far[0] > 10 and np.isinf(far[1]) and np.isnan(far[2])


def test_lean_predictors_equal_the_estimators(rng):
    X = rng.uniform(-2, 2, (250, 3))
    y = np.sin(X[:, 0]) + 0.3 * X[:, 1] + 0.05 * rng.standard_normal(250)
    rvr = RVR(width=1.0).fit(X, y)
    Xt = rng.uniform(-3, 3, (60, 3))
    mean, std = rvr.predict(Xt, return_std=True)
    lean_mean, lean_std = LeanRVR.from_estimator(rvr).predict(Xt)
    # the same sums in another order (torch matrix products against sequential loops)
    np.testing.assert_allclose(lean_mean, mean, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(lean_std, std, rtol=1e-12, atol=1e-12)
    Xc = np.vstack([rng.normal(c, 1, (40, 2)) for c in [(0, 0), (3, 0), (0, 3), (3, 3)]])
    yc = np.repeat(["a", "b", "c", "d"], 40)
    tree = HierarchicalClassifier(RVC(width=2.0)).fit(Xc, yc)
    np.testing.assert_allclose(
        LeanTree.from_classifier(tree).predict_proba(Xc), tree.predict_proba(Xc),
        rtol=1e-12, atol=1e-12,
    )  # fmt: skip
    with pytest.raises(ValueError, match="RBF"):
        LeanRVR.from_estimator(RVR(kernel="linear").fit(X, y))


def _blobs(rng, centres, n):
    X = np.vstack([rng.normal(c, 0.5, (n, 2)) for c in centres])
    y = np.repeat([f"f{i + 1}" for i in range(len(centres))], n)
    return X, y


def test_isolator_groups_and_probabilities(rng):
    from bayes_fdi.calibration import TemperatureScaler

    # f1 and f2 overlap completely, f3 stands apart
    centres = [(0, 0), (0, 0), (5, 5)]
    X, y = _blobs(rng, centres, 40)
    iso = FaultIsolator(calibrator=TemperatureScaler()).fit(
        X, y, validation=_blobs(rng, centres, 40), calibration=_blobs(rng, centres, 40)
    )
    assert iso.groups_ == (("f1", "f2"), ("f3",))
    assert iso.group_labels_ == ("f1|f2", "f3")
    p = iso.fault_proba(_blobs(rng, centres, 10)[0])
    np.testing.assert_allclose(p.sum(axis=1), 1.0, rtol=1e-12)
    gp = p @ iso.membership_
    np.testing.assert_allclose(gp[:, 0], p[:, 0] + p[:, 1], rtol=1e-12)
    assert iso.temperature() is not None and iso.temperature() > 0


def test_one_group_has_probability_one_and_no_calibrator(rng):
    from bayes_fdi.calibration import TemperatureScaler

    # two faults the validation cannot tell apart: one group, certain, nothing to calibrate
    centres = [(0, 0), (0, 0)]
    X, y = _blobs(rng, centres, 40)
    iso = FaultIsolator(calibrator=TemperatureScaler()).fit(
        X, y, validation=_blobs(rng, centres, 40), calibration=_blobs(rng, centres, 40)
    )
    assert iso.groups_ == (("f1", "f2"),)
    assert iso.calibrator_ is None
    rows = _blobs(rng, centres, 5)[0]
    out = iso.run(rows)
    np.testing.assert_allclose(out.group_proba, 1.0, rtol=1e-12)
    np.testing.assert_allclose(out.fault_proba, iso.fault_proba(rows), rtol=1e-10)


@pytest.mark.parametrize("classifier", ["tree", "forest"])
def test_isolator_run_equals_the_temperature_scaled_group_sums(rng, classifier):
    from bayes_fdi.calibration import TemperatureScaler
    from bayes_fdi.diagnosis.isolation import ForestClassifier

    centres = [(0, 0), (0, 0), (5, 5)]
    X, y = _blobs(rng, centres, 40)
    clf = ForestClassifier(n_estimators=25, random_state=0) if classifier == "forest" else None
    iso = FaultIsolator(clf, calibrator=TemperatureScaler()).fit(
        X, y, validation=_blobs(rng, centres, 40), calibration=_blobs(rng, centres, 40)
    )
    assert iso.rows_independent  # both run the compiled pass
    rows = _blobs(rng, centres, 10)[0]
    rows[3] = np.nan  # no signature this second
    out = iso.run(rows)
    assert np.isnan(out.fault_proba[3]).all() and np.isnan(out.novelty[3])
    ok = np.arange(rows.shape[0]) != 3
    # second implementation: the calibrator's own transform of the tree's group sums, shared
    # back to the faults in proportion (a group of probability 0 passes its own on)
    p = iso.fault_proba(rows[ok])
    gp = p @ iso.membership_
    g = iso.calibrator_.transform(gp)
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(gp[:, iso.group_of_] > 0, p / gp[:, iso.group_of_], 1.0)
    np.testing.assert_allclose(out.group_proba[ok], g, rtol=1e-10, atol=1e-15)
    np.testing.assert_allclose(out.fault_proba[ok], g[:, iso.group_of_] * share, rtol=1e-10)
    np.testing.assert_array_equal(out.novelty[ok], iso.novelty_.score(rows[ok]))
    one = iso.update(rows[5])
    np.testing.assert_array_equal(one.group_proba, out.group_proba[5])
    assert one.novelty == out.novelty[5]
    # each row's numbers are those it gets alone, wherever it stands in the batch
    for i in range(rows.shape[0]):
        alone = iso.run(rows[i : i + 1])
        np.testing.assert_array_equal(alone.fault_proba[0], out.fault_proba[i])
    backwards = iso.run(rows[::-1].copy())
    np.testing.assert_array_equal(backwards.group_proba[::-1], out.group_proba)


def test_the_window_reports_its_complete_seconds_by_hand():
    # DD on at 2-5 and 7-8; second 4 has a NaN residual (skipped by the window); the reference
    # exists from second 0
    n = 9
    dd = np.array([0, 0, 1, 1, 1, 1, 0, 1, 1], dtype=bool)
    cols = [np.full(n, 0.01), np.full(n, 0.02), np.full(n, 0.5), np.full(n, 0.5),
            np.full(n, 0.4), np.full(n, 0.87), np.full(n, 0.65), np.full(n, 0.22)]  # fmt: skip
    cols[0][4] = np.nan
    seconds = np.full(n, -1.0)
    window = SignatureWindow()
    feats, state = window.run(SignatureInputs(dd, *cols), seconds=seconds)
    np.testing.assert_array_equal(seconds, [0, 0, 1, 2, 2, 3, 0, 1, 2])
    # features exist exactly where the window holds a complete second
    np.testing.assert_array_equal(np.isfinite(feats).all(axis=1), seconds > 0)
    assert state.count[0] == seconds[-1]
    # stacked runs and a chunked run report the same seconds
    stacked = np.empty((2, n))
    both = SignatureInputs(*(np.stack([c, c]) for c in (dd, *cols)))
    fresh = window.init_state()
    pair = type(fresh)(*(np.stack([f, f]) for f in fresh))
    window.run_stacked(both, pair, seconds=stacked)
    np.testing.assert_array_equal(stacked, [seconds, seconds])
    first = np.empty(4)
    _, mid = window.run(SignatureInputs(dd[:4], *(c[:4] for c in cols)), seconds=first)
    rest = np.empty(n - 4)
    window.run(SignatureInputs(dd[4:], *(c[4:] for c in cols)), mid, seconds=rest)
    np.testing.assert_array_equal(np.concatenate([first, rest]), seconds)
    with pytest.raises(ValueError, match="seconds must be a C-contiguous float64 array"):
        window.run(SignatureInputs(dd, *cols), seconds=np.empty(n, dtype=np.float32))
