"""Fault isolation: residual features, the k-means tree of classifiers, the online isolator.

- `bayes_fdi.diagnosis.isolation.features`: per-window residual features of the offline
  diagnoser (a registry; the paper's mean residuals by default).
- `bayes_fdi.diagnosis.isolation.tree`: the k-means designed binary tree of probabilistic
  classifiers (RVCs by default), whose leaf probabilities are products along the paths.
- `bayes_fdi.diagnosis.isolation.tree_design`: the tree's design by recursive 2-means on the
  class centroids.
- `bayes_fdi.diagnosis.isolation.svm`: the paper's SVM node classifier (the baseline).
- `bayes_fdi.diagnosis.isolation.signatures`: the online diagnoser's signatures over the window
  since a detection (`SignatureWindow`, an online component with its `SignatureState`).
- `bayes_fdi.diagnosis.isolation.isolator`: `FaultIsolator` (isolability groups, calibrated
  group probabilities, per-second isolation of signatures).
- `bayes_fdi.diagnosis.isolation.class_novelty`: `ClassNovelty`, how unlike every fault's
  training signatures a signature is.
- `bayes_fdi.diagnosis.isolation.compiled_tree`: `LeanTree`, the compiled predictor of a tree
  of RVCs.
- `bayes_fdi.diagnosis.isolation.forest`: `ForestClassifier`, a random forest kept as arrays
  with a compiled predictor (an alternative isolation classifier of a commissioned valve and of
  the default model).
- `bayes_fdi.diagnosis.isolation.compiled_isolation`: the isolator's per-second pass of the tree
  or the forest, compiled (group sums, temperature, novelty, row by row).

May import `bayes_fdi.rvm`, `bayes_fdi.datasets`, `bayes_fdi.diagnosis.normal_models`,
`bayes_fdi.diagnosis.component_state` and the foundation.
"""

from bayes_fdi.diagnosis.isolation.class_novelty import ClassNovelty
from bayes_fdi.diagnosis.isolation.compiled_tree import LeanTree
from bayes_fdi.diagnosis.isolation.features import (
    DEFAULT_FEATURES,
    FEATURES,
    extract_features,
    register_feature,
    window_bounds,
)
from bayes_fdi.diagnosis.isolation.forest import ForestClassifier
from bayes_fdi.diagnosis.isolation.isolator import FaultIsolator, IsolationOutput
from bayes_fdi.diagnosis.isolation.signatures import (
    ISOLATION_FEATURES,
    SignatureInputs,
    SignatureState,
    SignatureWindow,
)
from bayes_fdi.diagnosis.isolation.svm import SVMClassifier, svm_classifier
from bayes_fdi.diagnosis.isolation.tree import PAPER_TREE, HierarchicalClassifier, TreeNode
from bayes_fdi.diagnosis.isolation.tree_design import design_tree

__all__ = [
    "DEFAULT_FEATURES",
    "FEATURES",
    "ISOLATION_FEATURES",
    "PAPER_TREE",
    "ClassNovelty",
    "FaultIsolator",
    "ForestClassifier",
    "HierarchicalClassifier",
    "IsolationOutput",
    "LeanTree",
    "SVMClassifier",
    "SignatureInputs",
    "SignatureState",
    "SignatureWindow",
    "TreeNode",
    "design_tree",
    "extract_features",
    "register_feature",
    "svm_classifier",
    "window_bounds",
]
