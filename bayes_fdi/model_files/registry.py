"""Persisted classes: the stable names under which model files store classes, and the allow-list.

A model file names the class of every object it holds by a *stable name* (``"OnlineDiagnoser"``,
``"rvm.RVR"``, ``"sklearn.SVC"``): :data:`PERSISTED` maps each stable name to where the class
lives now (``"module:QualName"``, preferably a package's public face), so moving a class inside
the package changes one line here and no model file. Files written by bayes_fdi 0.1.0 named
classes by their ``"module:QualName"`` at the time; :data:`LEGACY_NAMES` maps those spellings to
the stable names, so those files still load.

The table is an allow-list. Loading imports only the modules this table names, never a module
named by a file, and constructs only registered classes: a file naming anything else (say
``bayes_fdi.__main__``) is refused before any import. A plug-in's class is registered in the
running process with `register_persistable` (in the process that saves and in the one that
loads).
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = [
    "LEGACY_NAMES",
    "PERSISTED",
    "is_namedtuple",
    "is_persistable",
    "register_persistable",
    "resolve_class",
    "stable_name",
]

#: Stable name -> ``"module:QualName"`` of the class today.
PERSISTED: dict[str, str] = {
    # the diagnosers and their parts
    "FaultDiagnoser": "bayes_fdi.diagnosis:FaultDiagnoser",
    "OnlineDiagnoser": "bayes_fdi.diagnosis:OnlineDiagnoser",
    "StreamState": "bayes_fdi.diagnosis:StreamState",
    "NormalModels": "bayes_fdi.diagnosis.normal_models:NormalModels",
    "DynamicNormalModels": "bayes_fdi.diagnosis.normal_models:DynamicNormalModels",
    "KernelRidgeRegressor": "bayes_fdi.diagnosis.normal_models:KernelRidgeRegressor",
    "StdScaler": "bayes_fdi.diagnosis.normal_models:StdScaler",
    "CrossFitScales": "bayes_fdi.diagnosis.normal_models.interval_calibration:CrossFitScales",
    "EvidenceGridResult": "bayes_fdi.diagnosis.normal_models:EvidenceGridResult",
    "GAResult": "bayes_fdi.diagnosis.normal_models:GAResult",
    "LeanRVR": "bayes_fdi.diagnosis.normal_models.compiled:LeanRVR",
    "NormalModelsParams": "bayes_fdi.diagnosis.normal_models.dynamic_kernel:NormalModelsParams",
    "NormalModelsState": "bayes_fdi.diagnosis.normal_models.dynamic_kernel:NormalModelsState",
    "TrainingCurvePoint": "bayes_fdi.diagnosis.normal_models:TrainingCurvePoint",
    "TrainingSize": "bayes_fdi.diagnosis.normal_models:TrainingSize",
    "LeanTree": "bayes_fdi.diagnosis.isolation:LeanTree",
    "ARWhitener": "bayes_fdi.diagnosis.detection:ARWhitener",
    "WhitenState": "bayes_fdi.diagnosis.detection:WhitenState",
    "CUSUM": "bayes_fdi.diagnosis.detection:CUSUM",
    "CUSUMState": "bayes_fdi.diagnosis.detection:CUSUMState",
    "GLR": "bayes_fdi.diagnosis.detection:GLR",
    "GLRState": "bayes_fdi.diagnosis.detection:GLRState",
    "TwoSpeedCUSUM": "bayes_fdi.diagnosis.detection:TwoSpeedCUSUM",
    "TwoSpeedCUSUMState": "bayes_fdi.diagnosis.detection:TwoSpeedCUSUMState",
    "VarianceHoldCUSUM": "bayes_fdi.diagnosis.detection:VarianceHoldCUSUM",
    "VarianceHoldCUSUMState": "bayes_fdi.diagnosis.detection:VarianceHoldCUSUMState",
    "DetectionDecision": "bayes_fdi.diagnosis.detection:DetectionDecision",
    "DecisionState": "bayes_fdi.diagnosis.detection:DecisionState",
    "HierarchicalClassifier": "bayes_fdi.diagnosis.isolation:HierarchicalClassifier",
    "TreeNode": "bayes_fdi.diagnosis.isolation:TreeNode",
    "SVMClassifier": "bayes_fdi.diagnosis.isolation:SVMClassifier",
    "ForestClassifier": "bayes_fdi.diagnosis.isolation:ForestClassifier",
    "FaultIsolator": "bayes_fdi.diagnosis.isolation:FaultIsolator",
    "ClassNovelty": "bayes_fdi.diagnosis.isolation:ClassNovelty",
    "SignatureWindow": "bayes_fdi.diagnosis.isolation:SignatureWindow",
    "SignatureState": "bayes_fdi.diagnosis.isolation:SignatureState",
    "InputEnvelope": "bayes_fdi.diagnosis.online:InputEnvelope",
    "EnvelopeState": "bayes_fdi.diagnosis.online:EnvelopeState",
    "FitProofState": "bayes_fdi.diagnosis.online:FitProofState",
    "RunState": "bayes_fdi.diagnosis.online:RunState",
    "PerOutput": "bayes_fdi.diagnosis.online:PerOutput",
    "NoveltyReference": "bayes_fdi.diagnosis.seva:NoveltyReference",
    "SevaThresholds": "bayes_fdi.diagnosis.seva:SevaThresholds",
    "SevaStatus": "bayes_fdi.diagnosis.seva:SevaStatus",
    "SevaRecord": "bayes_fdi.diagnosis.seva:SevaRecord",
    "ClassDistribution": "bayes_fdi.diagnosis.seva:ClassDistribution",
    # recalibrators
    "TemperatureScaler": "bayes_fdi.calibration:TemperatureScaler",
    "AgeTemperatureScaler": "bayes_fdi.calibration:AgeTemperatureScaler",
    "TopLabelScaler": "bayes_fdi.calibration:TopLabelScaler",
    "DirichletScaler": "bayes_fdi.calibration:DirichletScaler",
    "NodeCalibration": "bayes_fdi.calibration:NodeCalibration",
    # relevance vector machines
    "rvm.RVR": "bayes_fdi.rvm:RVR",
    "rvm.RVC": "bayes_fdi.rvm:RVC",
    "rvm.RBF": "bayes_fdi.rvm:RBF",
    "rvm.Linear": "bayes_fdi.rvm:Linear",
    "rvm.Polynomial": "bayes_fdi.rvm:Polynomial",
    "rvm.Product": "bayes_fdi.rvm:Product",
    "rvm.Scaled": "bayes_fdi.rvm:Scaled",
    "rvm.Sum": "bayes_fdi.rvm:Sum",
    "rvm.SBLResult": "bayes_fdi.rvm:SBLResult",
    "rvm.Polish": "bayes_fdi.rvm.sbl:Polish",
    "rvm.WidthSearch": "bayes_fdi.rvm.width:WidthSearch",
    # scikit-learn classes found inside the baselines and recalibrators (public import paths)
    "sklearn.StandardScaler": "sklearn.preprocessing:StandardScaler",
    "sklearn.SVC": "sklearn.svm:SVC",
    "sklearn.CalibratedClassifierCV": "sklearn.calibration:CalibratedClassifierCV",
    "sklearn._CalibratedClassifier": "sklearn.calibration:_CalibratedClassifier",
    "sklearn._SigmoidCalibration": "sklearn.calibration:_SigmoidCalibration",
    "sklearn.IsotonicRegression": "sklearn.isotonic:IsotonicRegression",
    "sklearn.LogisticRegression": "sklearn.linear_model:LogisticRegression",
}

#: ``"module:QualName"`` spellings of bayes_fdi 0.1.0 (format version 1) -> stable name.
LEGACY_NAMES: dict[str, str] = {
    "bayes_fdi.diagnosis.diagnoser:FaultDiagnoser": "FaultDiagnoser",
    "bayes_fdi.diagnosis.online:OnlineDiagnoser": "OnlineDiagnoser",
    "bayes_fdi.diagnosis.online_state:StreamState": "StreamState",
    "bayes_fdi.diagnosis.normal_models:NormalModels": "NormalModels",
    "bayes_fdi.diagnosis.dynamic_models:DynamicNormalModels": "DynamicNormalModels",
    "bayes_fdi.diagnosis.baselines:KernelRidgeRegressor": "KernelRidgeRegressor",
    "bayes_fdi.diagnosis.interval_scaling:StdScaler": "StdScaler",
    "bayes_fdi.diagnosis.interval_calibration:CrossFitScales": "CrossFitScales",
    "bayes_fdi.diagnosis.width_search:EvidenceGridResult": "EvidenceGridResult",
    "bayes_fdi.diagnosis.width_search:GAResult": "GAResult",
    "bayes_fdi.diagnosis.lean_predictors:LeanRVR": "LeanRVR",
    "bayes_fdi.diagnosis.lean_predictors:LeanTree": "LeanTree",
    "bayes_fdi.diagnosis.whitening:ARWhitener": "ARWhitener",
    "bayes_fdi.diagnosis.detection:CUSUM": "CUSUM",
    "bayes_fdi.diagnosis.detection:GLR": "GLR",
    "bayes_fdi.diagnosis.tree:HierarchicalClassifier": "HierarchicalClassifier",
    "bayes_fdi.diagnosis.tree:TreeNode": "TreeNode",
    "bayes_fdi.diagnosis.baselines:SVMClassifier": "SVMClassifier",
    "bayes_fdi.diagnosis.isolation:FaultIsolator": "FaultIsolator",
    "bayes_fdi.diagnosis.isolation:ClassNovelty": "ClassNovelty",
    "bayes_fdi.diagnosis.novelty:NoveltyReference": "NoveltyReference",
    "bayes_fdi.diagnosis.seva_rules:SevaThresholds": "SevaThresholds",
    "bayes_fdi.diagnosis.seva_record:SevaStatus": "SevaStatus",
    "bayes_fdi.diagnosis.seva_record:SevaRecord": "SevaRecord",
    "bayes_fdi.diagnosis.seva_record:ClassDistribution": "ClassDistribution",
    "bayes_fdi.calibration.recalibration:TemperatureScaler": "TemperatureScaler",
    "bayes_fdi.calibration.recalibration:DirichletScaler": "DirichletScaler",
    "bayes_fdi.calibration.nodes:NodeCalibration": "NodeCalibration",
    "bayes_fdi.rvm.regression:RVR": "rvm.RVR",
    "bayes_fdi.rvm.classification:RVC": "rvm.RVC",
    "bayes_fdi.rvm.kernels:RBF": "rvm.RBF",
    "bayes_fdi.rvm.kernels:Linear": "rvm.Linear",
    "bayes_fdi.rvm.kernels:Polynomial": "rvm.Polynomial",
    "bayes_fdi.rvm.kernels:Product": "rvm.Product",
    "bayes_fdi.rvm.kernels:Scaled": "rvm.Scaled",
    "bayes_fdi.rvm.kernels:Sum": "rvm.Sum",
    "bayes_fdi.rvm.sbl_numerics:SBLResult": "rvm.SBLResult",
    "bayes_fdi.rvm.sbl_polish:Polish": "rvm.Polish",
    "bayes_fdi.rvm.width:WidthSearch": "rvm.WidthSearch",
    "sklearn.preprocessing._data:StandardScaler": "sklearn.StandardScaler",
    "sklearn.svm._classes:SVC": "sklearn.SVC",
    "sklearn.calibration:CalibratedClassifierCV": "sklearn.CalibratedClassifierCV",
    "sklearn.calibration:_CalibratedClassifier": "sklearn._CalibratedClassifier",
    "sklearn.calibration:_SigmoidCalibration": "sklearn._SigmoidCalibration",
    "sklearn.isotonic:IsotonicRegression": "sklearn.IsotonicRegression",
    "sklearn.linear_model._logistic:LogisticRegression": "sklearn.LogisticRegression",
}

#: Classes registered in this process by `register_persistable`: stable name -> class.
_PLUGINS: dict[str, type] = {}
#: Classes of the table already imported: stable name -> class (filled on first use).
_RESOLVED: dict[str, type] = {}
#: The table's classes -> their stable names (filled by the first `stable_name`).
_BY_CLASS: dict[type, str] = {}


def is_namedtuple(cls: type) -> bool:
    """Whether ``cls`` is a named tuple class (saved by its fields, not its ``__dict__``)."""
    return issubclass(cls, tuple) and hasattr(cls, "_fields")


def _import(location: str) -> type:
    module_name, qualname = location.split(":")
    obj: Any = importlib.import_module(module_name)
    for part in qualname.split("."):
        obj = getattr(obj, part)
    return obj


def _lookup(name: str) -> type | None:
    """The class registered under stable ``name`` (None when there is none)."""
    if name in _PLUGINS:
        return _PLUGINS[name]
    if name not in PERSISTED:
        return None
    if name not in _RESOLVED:
        _RESOLVED[name] = _import(PERSISTED[name])
    return _RESOLVED[name]


def stable_name(cls: type) -> str | None:
    """The stable name under which files store ``cls``, or None when it is not persistable.

    The first call imports the modules of :data:`PERSISTED` (to know their classes).
    """
    for name, known in _PLUGINS.items():
        if known is cls:
            return name
    if not _BY_CLASS:
        _BY_CLASS.update({_lookup(name): name for name in PERSISTED})
    return _BY_CLASS.get(cls)


def is_persistable(cls: type) -> bool:
    """Whether instances of ``cls`` may be saved (``cls`` is registered)."""
    return stable_name(cls) is not None


def register_persistable(cls: type, name: str | None = None) -> type:
    """Allow instances of ``cls`` (a plug-in's class with a ``__dict__``, or a named tuple) in
    model files, under the stable ``name`` (default ``"plugin.<module>.<QualName>"``).

    Usable as a class decorator; returns ``cls``. Register it in the process that saves and in the
    one that loads.
    """
    if not isinstance(cls, type):
        raise ValueError(f"register_persistable expects a class, got {cls!r}")
    name = name or f"plugin.{cls.__module__}.{cls.__qualname__}"
    if name in PERSISTED or (name in _PLUGINS and _PLUGINS[name] is not cls):
        raise ValueError(f"the model-file name {name!r} is already taken by another class")
    _PLUGINS[name] = cls
    return cls


def resolve_class(name: Any, source: str) -> type:
    """The class a file names (a stable name, or a 0.1.0 ``"module:QualName"`` spelling).

    Nothing the file names is imported: only the modules of :data:`PERSISTED`. A name that is not
    registered raises a `ValueError` naming ``source`` (the file).
    """
    if not isinstance(name, str):
        raise ValueError(f"{source}: invalid class name {name!r}")
    stable = LEGACY_NAMES.get(name, name)
    cls = _lookup(stable)
    if cls is None:
        raise ValueError(f"{source}: class {name!r} is not allowed in a bayes_fdi model file")
    return cls
