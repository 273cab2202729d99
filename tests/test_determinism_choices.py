"""The pipeline's discrete choices do not depend on the last bits of their inputs.

Each choice that compares floating-point scores (the tree's k-means split, the normal models'
kernel width, the recalibrator) treats near-equal scores as a tie and breaks it by a fixed rule;
here the scores are tied exactly (by symmetry or by construction) and then perturbed in their
last bits, as another BLAS code path would, and the choice must not move.
"""

from __future__ import annotations

import numpy as np
import pytest

from bayes_fdi.diagnosis.isolation.tree_design import INERTIA_RTOL, design_tree
from bayes_fdi.diagnosis.normal_models.width_search import EVIDENCE_TIE_NATS, evidence_grid_search

CORNERS = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])


def test_kmeans_split_of_a_square_is_the_same_for_every_seed_and_last_bit():
    # Pairing the corners horizontally or vertically gives the same inertia (1.0): a tie by
    # symmetry, broken by the fixed order of the partitions (corner 0 with corner 1 here).
    classes = ["a", "b", "c", "d"]
    rng = np.random.default_rng(0)
    trees = set()
    for seed in range(8):
        for _ in range(3):
            wobble = CORNERS * (1 + 1e-13 * rng.standard_normal(CORNERS.shape))
            trees.add(design_tree(wobble, classes, random_state=seed))
    assert trees == {(("a", "b"), ("c", "d"))}


def test_kmeans_split_prefers_a_real_difference_over_the_tie_rule():
    # stretch the square: the vertical pairs are now closer (inertia 1.0 vs 1.0 * 1.1**2)
    stretched = CORNERS * np.array([1.1, 1.0])
    assert design_tree(stretched, ["a", "b", "c", "d"]) == (("a", "d"), ("b", "c"))
    assert 1.1**2 - 1 > 1e3 * INERTIA_RTOL


class _Fixed:
    """A regressor whose log evidence is a given function of its width."""

    def __init__(self, width, evidence):
        self.width, self.evidence = width, evidence

    def fit(self, X, y):
        self.log_evidence_ = self.evidence[self.width]
        return self


@pytest.mark.parametrize("delta", [0.1, 0.9])
def test_width_grid_near_tie_goes_to_the_first_width(delta):
    # two widths within EVIDENCE_TIE_NATS of each other (whatever their order in the last
    # digits) are a tie: the first in grid order wins
    evidence = {0.1: 1000.0, 0.2: 1000.0 + delta * EVIDENCE_TIE_NATS, 0.4: 900.0}
    res = evidence_grid_search(
        lambda w: _Fixed(w, evidence), np.zeros((5, 1)), {"X": np.zeros(5)}, [0.1, 0.2, 0.4]
    )
    assert res.width == 0.1


def test_width_grid_real_difference_wins():
    evidence = {0.1: 1000.0, 0.2: 1000.0 + 1e3 * EVIDENCE_TIE_NATS, 0.4: 900.0}
    res = evidence_grid_search(
        lambda w: _Fixed(w, evidence), np.zeros((5, 1)), {"X": np.zeros(5)}, [0.1, 0.2, 0.4]
    )
    assert res.width == 0.2
