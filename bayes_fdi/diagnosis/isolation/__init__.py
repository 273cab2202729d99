"""Fault isolation: residual features, the k-means tree of classifiers, the online isolator.

- `bayes_fdi.diagnosis.isolation.features`: per-window residual features of the offline
  diagnoser (a registry; the paper's mean residuals by default).
- `bayes_fdi.diagnosis.isolation.tree`: the k-means designed binary tree of probabilistic
  classifiers (RVCs by default), whose leaf probabilities are products along the paths.
- `bayes_fdi.diagnosis.isolation.tree_design`: the tree's design by recursive 2-means on the
  class centroids.
- `bayes_fdi.diagnosis.isolation.svm`: the paper's SVM node classifier (the baseline).
- `bayes_fdi.diagnosis.isolation.isolator`: the online diagnoser's signatures over the window
  since a detection, its `FaultIsolator` (isolability groups, calibrated group probabilities,
  the novelty of a signature).

May import `bayes_fdi.rvm`, `bayes_fdi.datasets`, `bayes_fdi.diagnosis.normal_models` and the
foundation.
"""

from bayes_fdi.diagnosis.isolation.features import (
    DEFAULT_FEATURES,
    FEATURES,
    extract_features,
    register_feature,
    window_bounds,
)
from bayes_fdi.diagnosis.isolation.isolator import FaultIsolator
from bayes_fdi.diagnosis.isolation.svm import SVMClassifier, svm_classifier
from bayes_fdi.diagnosis.isolation.tree import PAPER_TREE, HierarchicalClassifier, TreeNode
from bayes_fdi.diagnosis.isolation.tree_design import design_tree

__all__ = [
    "DEFAULT_FEATURES",
    "FEATURES",
    "PAPER_TREE",
    "FaultIsolator",
    "HierarchicalClassifier",
    "SVMClassifier",
    "TreeNode",
    "design_tree",
    "extract_features",
    "register_feature",
    "svm_classifier",
    "window_bounds",
]
