"""Fault diagnosis of an actuator, by concept, shared by the offline and the online diagnoser.

- `bayes_fdi.diagnosis.normal_models`: fault-free models of X and F (the residual generators).
- `bayes_fdi.diagnosis.detection`: whitening, sequential tests and thresholds (online).
- `bayes_fdi.diagnosis.isolation`: residual features, the k-means tree of RVM (or SVM)
  classifiers, the online isolator with its isolability groups and novelty.
- `bayes_fdi.diagnosis.seva`: the self-validating output (records, statuses, rules).
- `bayes_fdi.diagnosis.fault_diagnoser`: `FaultDiagnoser`, the paper's offline pipeline (one
  diagnosis per run or window) and its SVM baseline `svm_fault_diagnoser`.
- `bayes_fdi.diagnosis.online`: `OnlineDiagnoser`, the 1 Hz diagnoser (detection, isolation
  and SEVA status every second, ``run`` over a recording or ``update`` per sample).
- `bayes_fdi.diagnosis.component_state`: how the online components' states (named tuples of
  arrays) are checked, copied and stacked.

Which diagnoser when: `FaultDiagnoser` labels whole runs (or windows) the way the paper does,
for studies on labelled datasets; `OnlineDiagnoser` is the field device, second by second.

May import `bayes_fdi.rvm`, `bayes_fdi.datasets`, `bayes_fdi.model_files` and the foundation;
never `bayes_fdi.calibration` (which builds on it) or an application.
"""

from bayes_fdi.diagnosis.fault_diagnoser import FaultDiagnoser, svm_fault_diagnoser
from bayes_fdi.diagnosis.isolation import (
    DEFAULT_FEATURES,
    FEATURES,
    PAPER_TREE,
    HierarchicalClassifier,
    SVMClassifier,
    TreeNode,
    design_tree,
    extract_features,
    register_feature,
    svm_classifier,
    window_bounds,
)
from bayes_fdi.diagnosis.normal_models import (
    MODEL_INPUTS,
    WIDTH_GRID,
    DynamicNormalModels,
    EvidenceGridResult,
    GAResult,
    KernelRidgeRegressor,
    NegativePressureDropWarning,
    NormalModels,
    StdScaler,
    evidence_grid_search,
    genetic_width_search,
    input_names,
    model_inputs,
)
from bayes_fdi.diagnosis.online import OnlineDiagnoser, StreamState
from bayes_fdi.diagnosis.seva import (
    ClassDistribution,
    NoveltyReference,
    SevaRecord,
    SevaStatus,
    SevaThresholds,
    seva_records,
)

__all__ = [
    "DEFAULT_FEATURES",
    "FEATURES",
    "MODEL_INPUTS",
    "PAPER_TREE",
    "WIDTH_GRID",
    "ClassDistribution",
    "DynamicNormalModels",
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
