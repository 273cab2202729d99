"""Saving fitted RVMs without pickle, and reading the files back (the format).

`save` writes a fitted estimator; `read_model_file` checks a file's format and returns its
metadata and arrays; `bayes_fdi.rvm.loading.load` rebuilds the estimator from them (it sits
above the estimators, so this module knows none of them: no import circle).

File format (``.npz``, read with ``allow_pickle=False``):

* ``metadata`` -- a 0-d unicode array holding JSON: ``format`` (``"bayes_fdi.rvm"``),
  ``format_version`` (:data:`FORMAT_VERSION`), ``estimator`` (``"RVR"`` or ``"RVC"``),
  ``params`` (constructor parameters; a kernel object as ``{"kernel": {...}}`` from
  :meth:`~bayes_fdi.rvm.kernels.Kernel.to_dict`), ``models`` (one entry per binary model:
  ``beta``, ``log_evidence``, ``n_iter``, ``converged``), ``width``, ``n_features_in``,
  ``dtype`` and ``bayes_fdi_version``.
* ``X_fit`` -- the training inputs (the candidate basis; relevance vectors are rows of it).
* per binary model ``k`` (one for RVR and binary RVC, one per class for one-vs-rest):
  ``m{k}_active`` (active candidate-basis indices, bias = 0 when ``bias``), ``m{k}_mean``,
  ``m{k}_covariance``, ``m{k}_alpha``, ``m{k}_evidence_trace``.
* ``classes`` -- RVC only: the class labels (numeric or string).

A round trip reproduces predictions exactly (the same float arrays feed the same code).
Unreadable files, missing entries, inconsistent shapes and unknown formats or versions
raise :class:`ValueError`.
"""

from __future__ import annotations

import json
import os
import zipfile
from typing import Any

import numpy as np

from bayes_fdi.rvm.kernels import Kernel, kernel_from_dict
from bayes_fdi.rvm.sparse_bayes import SBLResult

__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "read_model_file", "save"]

FORMAT_NAME = "bayes_fdi.rvm"
FORMAT_VERSION = 1
#: The estimator classes a file can hold (``metadata["estimator"]``).
ESTIMATORS: tuple[str, ...] = ("RVR", "RVC")


def _version() -> str:
    from bayes_fdi import __version__

    return __version__


def _params_to_json(params: dict[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in params.items():
        if key == "kernel" and isinstance(value, Kernel):
            out[key] = {"kernel": value.to_dict()}
        elif key == "kernel" and callable(value):
            raise ValueError("a model with a user-supplied callable kernel cannot be saved")
        elif key == "device":
            out[key] = None if value is None else str(value)
        elif isinstance(value, np.generic):
            out[key] = value.item()
        else:
            out[key] = value
    json.dumps(out)  # fail early on anything not serialisable
    return out


def _params_from_json(params: dict[str, Any]) -> dict[str, Any]:
    out = dict(params)
    if isinstance(out.get("kernel"), dict):
        out["kernel"] = kernel_from_dict(out["kernel"]["kernel"])
    return out


def _estimator_name(model: Any) -> str:
    """``"RVR"`` or ``"RVC"``: the saved estimator class (subclasses are saved as their base)."""
    for klass in type(model).__mro__:
        if klass.__name__ in ESTIMATORS and klass.__module__.startswith("bayes_fdi.rvm."):
            return klass.__name__
    raise ValueError(f"can only save RVR or RVC models, got {type(model).__name__}")


def save(model: Any, path: str | os.PathLike[str]) -> None:
    """Write a fitted :class:`~bayes_fdi.rvm.RVR` or :class:`~bayes_fdi.rvm.RVC` to ``path``.

    Parameters
    ----------
    model : RVR or RVC
        A fitted estimator.
    path : str or path-like
        Destination; numpy appends ``.npz`` if missing.

    Raises
    ------
    ValueError
        If the model uses a callable kernel or has labels that are neither numbers nor strings.
    """
    from sklearn.utils.validation import check_is_fitted

    estimator = _estimator_name(model)
    check_is_fitted(model)
    subs = [model] if getattr(model, "estimators_", None) is None else model.estimators_
    arrays: dict[str, np.ndarray] = {"X_fit": model._X_fit_.detach().cpu().numpy()}
    models_meta = []
    for k, sub in enumerate(subs):
        res: SBLResult = sub._result_
        arrays[f"m{k}_active"] = res.active.cpu().numpy().astype(np.int64)
        arrays[f"m{k}_mean"] = sub._mu_.detach().cpu().numpy()
        arrays[f"m{k}_covariance"] = sub._Sigma_.detach().cpu().numpy()
        arrays[f"m{k}_alpha"] = res.alpha.cpu().numpy()
        arrays[f"m{k}_evidence_trace"] = res.evidence_trace.cpu().numpy()
        models_meta.append(
            {
                "beta": None if np.isnan(res.beta) else float(res.beta),
                "log_evidence": float(res.log_evidence),
                "n_iter": int(res.n_iter),
                "converged": bool(res.converged),
            }
        )
    if estimator == "RVC":
        classes = np.asarray(model.classes_)
        if classes.dtype.kind == "O":
            if not all(isinstance(c, str) for c in classes):
                raise ValueError("class labels must be numbers or strings to be saved")
            classes = classes.astype(str)
        if classes.dtype.kind not in "biufU":
            raise ValueError(f"class labels of dtype {classes.dtype} cannot be saved")
        arrays["classes"] = classes
    meta = {
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "estimator": estimator,
        "params": _params_to_json(model.get_params()),
        "models": models_meta,
        "width": model.width_,
        "n_features_in": int(model.n_features_in_),
        "dtype": str(model._dtype_).removeprefix("torch."),
        "bayes_fdi_version": _version(),
    }
    np.savez(os.fspath(path), metadata=np.array(json.dumps(meta)), **arrays)


def read_model_file(path: str | os.PathLike[str]) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    try:
        with np.load(os.fspath(path), allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
    except FileNotFoundError:
        raise
    except (OSError, ValueError, zipfile.BadZipFile, EOFError, KeyError) as exc:
        raise ValueError(f"{os.fspath(path)!r} is not a readable RVM file ({exc})") from exc
    if "metadata" not in arrays:
        raise ValueError(f"{os.fspath(path)!r} has no RVM metadata")
    try:
        meta = json.loads(str(arrays.pop("metadata")))
    except json.JSONDecodeError as exc:
        raise ValueError(f"{os.fspath(path)!r} has corrupt metadata ({exc})") from exc
    if not isinstance(meta, dict) or meta.get("format") != FORMAT_NAME:
        raise ValueError(f"{os.fspath(path)!r} is not a {FORMAT_NAME} file")
    version = meta.get("format_version")
    if not isinstance(version, int) or version < 1 or version > FORMAT_VERSION:
        raise ValueError(
            f"{os.fspath(path)!r} has format version {version!r}; this bayes_fdi reads "
            f"versions 1..{FORMAT_VERSION}"
        )
    return meta, arrays
