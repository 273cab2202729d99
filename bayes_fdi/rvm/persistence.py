"""Saving and loading fitted RVMs without pickle.

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
import torch

from bayes_fdi.rvm.kernels import Kernel, kernel_from_dict
from bayes_fdi.rvm.sparse_bayes import SBLResult

__all__ = ["FORMAT_NAME", "FORMAT_VERSION", "load", "save"]

FORMAT_NAME = "bayes_fdi.rvm"
FORMAT_VERSION = 1


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

    from bayes_fdi.rvm.classification import RVC
    from bayes_fdi.rvm.regression import RVR

    if not isinstance(model, RVR | RVC):
        raise ValueError(f"can only save RVR or RVC models, got {type(model).__name__}")
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
    if isinstance(model, RVC):
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
        "estimator": type(model).__name__,
        "params": _params_to_json(model.get_params()),
        "models": models_meta,
        "width": model.width_,
        "n_features_in": int(model.n_features_in_),
        "dtype": str(model._dtype_).removeprefix("torch."),
        "bayes_fdi_version": _version(),
    }
    np.savez(os.fspath(path), metadata=np.array(json.dumps(meta)), **arrays)


def _read(path: str | os.PathLike[str]) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
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


def load(path: str | os.PathLike[str], *, device: str | torch.device | None = None) -> Any:
    """Read a model written by :func:`save` (or ``model.save``).

    Parameters
    ----------
    path : str or path-like
        The ``.npz`` file.
    device : str or torch.device, optional
        Where to put the model's tensors (default: CPU, or the saved ``device`` parameter).

    Returns
    -------
    RVR or RVC
        The fitted estimator; its predictions equal the saved model's exactly.

    Raises
    ------
    ValueError
        If the file is corrupt, of another format or version, or internally inconsistent.
    """
    from bayes_fdi.rvm.classification import RVC
    from bayes_fdi.rvm.regression import RVR

    meta, arrays = _read(path)
    name = os.fspath(path)
    try:
        cls = {"RVR": RVR, "RVC": RVC}[meta["estimator"]]
        params = _params_from_json(meta["params"])
        models_meta = list(meta["models"])
        width = meta["width"]
        n_features = int(meta["n_features_in"])
        dtype = {"float64": torch.float64, "float32": torch.float32}[meta["dtype"]]
        X_fit_np = arrays["X_fit"]
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"{name!r} has incomplete or invalid metadata ({exc!r})") from exc
    if cls is RVR and len(models_meta) != 1:
        raise ValueError(f"{name!r}: an RVR file must hold exactly one model")
    if X_fit_np.ndim != 2 or X_fit_np.shape[1] != n_features:
        raise ValueError(
            f"{name!r}: training inputs of shape {X_fit_np.shape} do not match metadata"
        )
    model = cls(**params)
    dev = (
        torch.device(device) if device is not None else torch.device(params.get("device") or "cpu")
    )
    X_fit = torch.tensor(X_fit_np, dtype=dtype, device=dev)
    model.n_features_in_ = n_features
    kern = model._resolve_kernel(width)
    n_basis = (1 if model.bias else 0) + (X_fit.shape[0] if kern is not None else n_features)

    def binary(k: int, target: Any) -> None:
        try:
            active = arrays[f"m{k}_active"]
            mean = arrays[f"m{k}_mean"]
            cov = arrays[f"m{k}_covariance"]
            alpha = arrays[f"m{k}_alpha"]
            trace = arrays[f"m{k}_evidence_trace"]
            info = models_meta[k]
        except (KeyError, IndexError) as exc:
            raise ValueError(f"{name!r} is missing model {k} ({exc!r})") from exc
        m = len(active)
        if (
            active.dtype.kind not in "iu"
            or mean.shape != (m,)
            or alpha.shape != (m,)
            or cov.shape != (m, m)
            or trace.ndim != 1
            or (m and (active.min() < 0 or active.max() >= n_basis))
        ):
            raise ValueError(f"{name!r}: arrays of model {k} have inconsistent shapes or indices")
        beta = info.get("beta")
        result = SBLResult(
            active=torch.tensor(active, dtype=torch.long, device=dev),
            mean=torch.tensor(mean, dtype=dtype, device=dev),
            covariance=torch.tensor(cov, dtype=dtype, device=dev),
            alpha=torch.tensor(alpha, dtype=dtype, device=dev),
            beta=float("nan") if beta is None else float(beta),
            evidence_trace=torch.tensor(trace, dtype=torch.float64),
            log_evidence=float(info["log_evidence"]),
            n_iter=int(info["n_iter"]),
            converged=bool(info["converged"]),
        )
        target._set_state(result, X_fit, kern, width, warn=False)
        if isinstance(target, RVR):
            if beta is None:
                raise ValueError(f"{name!r}: an RVR model needs a noise precision 'beta'")
            target.beta_ = float(beta)

    if cls is RVR:
        binary(0, model)
        return model
    if "classes" not in arrays:
        raise ValueError(f"{name!r}: an RVC file must hold the class labels")
    model.classes_ = arrays["classes"]
    n_classes = len(model.classes_)
    expected = 1 if n_classes == 2 else n_classes
    if n_classes < 2 or len(models_meta) != expected:
        raise ValueError(
            f"{name!r}: {n_classes} classes need {expected} binary models, found {len(models_meta)}"
        )
    if expected == 1:
        binary(0, model)
        model.estimators_ = None
        return model
    subs = []
    for k in range(expected):
        sub = RVC(**params)
        sub.classes_ = np.array([0, 1])
        sub.n_features_in_ = n_features
        binary(k, sub)
        sub.estimators_ = None
        subs.append(sub)
    model._adopt_one_vs_rest(subs, X_fit, width)
    return model
