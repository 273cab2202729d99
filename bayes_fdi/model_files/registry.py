"""Persistable classes: which classes a model file may hold, and the lookup of their names.

A saved object's class is named ``"module:QualName"`` (`class_name`). `is_persistable` says whether
`bayes_fdi.model_files.format.save` may write an instance (the rules are the module docstring
of `bayes_fdi.model_files.format`, "Persistable classes"); `resolve_class` turns a name read
from a file back into its class, importing only ``bayes_fdi`` modules and the classes of
:data:`SKLEARN_CLASSES` or registered with `register_persistable`, and refuses any other.
"""

from __future__ import annotations

import importlib
from typing import Any

__all__ = [
    "MODEL_PACKAGES",
    "SKLEARN_CLASSES",
    "class_name",
    "is_namedtuple",
    "is_persistable",
    "register_persistable",
    "resolve_class",
]

#: scikit-learn / scipy classes that may appear inside a saved model (``module:QualName``).
SKLEARN_CLASSES: frozenset[str] = frozenset(
    {
        "sklearn.preprocessing._data:StandardScaler",
        "sklearn.svm._classes:SVC",
        "sklearn.calibration:CalibratedClassifierCV",
        "sklearn.calibration:_CalibratedClassifier",
        "sklearn.calibration:_SigmoidCalibration",
        "sklearn.isotonic:IsotonicRegression",
        "sklearn.linear_model._logistic:LogisticRegression",
    }
)
#: Packages of the model layers: any class defined there may be saved (estimators, detectors,
#: kernels, scalers, recalibrators, result tuples).
MODEL_PACKAGES: tuple[str, ...] = (
    "bayes_fdi.rvm.",
    "bayes_fdi.diagnosis.",
    "bayes_fdi.calibration.",
)
#: Classes registered by `register_persistable` (``module:QualName``), e.g. a plug-in's.
_REGISTERED: set[str] = set()


def register_persistable(cls: type) -> type:
    """Allow instances of ``cls`` (a class with a ``__dict__``) in saved models; returns ``cls``.

    Usable as a class decorator. The classes of the model layers and the estimators and named
    tuples defined in ``bayes_fdi`` need no registration. A class defined elsewhere (a plug-in)
    must be registered in the process that saves and in the one that loads (its module is
    imported by the loader only because it was registered).
    """
    if not isinstance(cls, type):
        raise ValueError(f"register_persistable expects a class, got {cls!r}")
    _REGISTERED.add(class_name(cls))
    return cls


def class_name(cls: type) -> str:
    """``"module:QualName"`` of ``cls``: how model files name classes."""
    return f"{cls.__module__}:{cls.__qualname__}"


def is_namedtuple(cls: type) -> bool:
    """Whether ``cls`` is a named tuple class (saved by its fields, not its ``__dict__``)."""
    return issubclass(cls, tuple) and hasattr(cls, "_fields")


def is_persistable(cls: type) -> bool:
    """Whether instances of ``cls`` may be saved (the rules of the module docstring)."""
    name = class_name(cls)
    if name in SKLEARN_CLASSES or name in _REGISTERED:
        return True
    if cls.__module__.startswith(MODEL_PACKAGES):
        return True
    if not cls.__module__.startswith("bayes_fdi."):
        return False
    from sklearn.base import BaseEstimator

    return is_namedtuple(cls) or issubclass(cls, BaseEstimator)


def resolve_class(name: Any, source: str) -> type:
    """The class a file names, if it is persistable (imports only ``bayes_fdi`` modules)."""
    if not isinstance(name, str) or name.count(":") != 1:
        raise ValueError(f"{source}: invalid class name {name!r}")
    module_name, qualname = name.split(":")
    trusted = name in SKLEARN_CLASSES or name in _REGISTERED or module_name.startswith("bayes_fdi.")
    if not trusted:
        raise ValueError(f"{source}: class {name!r} is not allowed in a bayes_fdi model file")
    try:
        obj: Any = importlib.import_module(module_name)
        for part in qualname.split("."):
            obj = getattr(obj, part)
    except (ImportError, AttributeError) as exc:
        raise ValueError(f"{source}: class {name!r} does not exist in this bayes_fdi") from exc
    if not isinstance(obj, type) or class_name(obj) != name or not is_persistable(obj):
        raise ValueError(f"{source}: class {name!r} is not allowed in a bayes_fdi model file")
    return obj
