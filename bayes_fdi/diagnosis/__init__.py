"""Fault diagnosis: normal models, residuals, features, the isolation tree and the SEVA output.

- `bayes_fdi.diagnosis.model_inputs`: the normal models' inputs ``(CV, sqrt(P1 - P2), T1)`` and
  optional delayed commands.
- `bayes_fdi.diagnosis.width_search`: the kernel-width searches (summed evidence over a grid; the
  paper's GA).
- `bayes_fdi.diagnosis.normal_models`: `NormalModels`, the fault-free RVR models ``g1``, ``g2``
  of ``X`` and ``F`` and their residuals.
- `bayes_fdi.diagnosis.interval_scaling`: recalibration of their predictive standard deviations.
- `bayes_fdi.diagnosis.interval_calibration`: the cross-fitted factors per command-speed bin
  that `NormalModels` applies to them.
- `bayes_fdi.diagnosis.features`: residual features (a registry).
- `bayes_fdi.diagnosis.tree`: the k-means designed binary tree of classifiers.
- `bayes_fdi.diagnosis.baselines`: the SVM baseline through the same interfaces.
- `bayes_fdi.diagnosis.diagnoser`: `FaultDiagnoser`, the paper's offline pipeline.
- `bayes_fdi.diagnosis.seva`: the self-validating (SEVA) records of a diagnosis
  (`bayes_fdi.diagnosis.seva_record`: the record and its conversions;
  `bayes_fdi.diagnosis.seva_rules`: thresholds, screening and status rules;
  `bayes_fdi.diagnosis.novelty`: the nearest-neighbour novelty reference).
- `bayes_fdi.diagnosis.persistence`: model files of fitted diagnosers, without pickle
  (`bayes_fdi.diagnosis.model_codec`: the object tree as JSON and arrays;
  `bayes_fdi.diagnosis.persistable`: the classes a file may hold).
"""

from bayes_fdi.diagnosis.baselines import (
    KernelRidgeRegressor,
    SVMClassifier,
    svm_classifier,
    svm_fault_diagnoser,
)
from bayes_fdi.diagnosis.diagnoser import FaultDiagnoser
from bayes_fdi.diagnosis.features import (
    DEFAULT_FEATURES,
    FEATURES,
    extract_features,
    register_feature,
    window_bounds,
)
from bayes_fdi.diagnosis.interval_scaling import StdScaler
from bayes_fdi.diagnosis.model_inputs import (
    MODEL_INPUTS,
    NegativePressureDropWarning,
    input_names,
    model_inputs,
)
from bayes_fdi.diagnosis.normal_models import NormalModels
from bayes_fdi.diagnosis.online import OnlineDiagnoser
from bayes_fdi.diagnosis.online_state import StreamState
from bayes_fdi.diagnosis.seva import (
    ClassDistribution,
    NoveltyReference,
    SevaRecord,
    SevaStatus,
    SevaThresholds,
    seva_records,
)
from bayes_fdi.diagnosis.tree import PAPER_TREE, HierarchicalClassifier, TreeNode, design_tree
from bayes_fdi.diagnosis.width_search import (
    WIDTH_GRID,
    EvidenceGridResult,
    GAResult,
    evidence_grid_search,
    genetic_width_search,
)

__all__ = [
    "DEFAULT_FEATURES",
    "FEATURES",
    "MODEL_INPUTS",
    "PAPER_TREE",
    "WIDTH_GRID",
    "ClassDistribution",
    "EvidenceGridResult",
    "FaultDiagnoser",
    "GAResult",
    "HierarchicalClassifier",
    "KernelRidgeRegressor",
    "NegativePressureDropWarning",
    "NormalModels",
    "NoveltyReference",
    "OnlineDiagnoser",
    "SVMClassifier",
    "SevaRecord",
    "SevaStatus",
    "SevaThresholds",
    "StdScaler",
    "StreamState",
    "TreeNode",
    "design_tree",
    "evidence_grid_search",
    "extract_features",
    "genetic_width_search",
    "input_names",
    "model_inputs",
    "register_feature",
    "seva_records",
    "svm_classifier",
    "svm_fault_diagnoser",
    "window_bounds",
]
