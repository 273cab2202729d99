"""Loading fitted RVMs written by `bayes_fdi.rvm.persistence.save` (``RVR.save``, ``RVC.save``).

The file format is described in `bayes_fdi.rvm.persistence`.
"""

from __future__ import annotations

import os
from typing import Any

import numpy as np
import torch

from bayes_fdi.rvm.classification import RVC
from bayes_fdi.rvm.persistence import _params_from_json, read_model_file
from bayes_fdi.rvm.regression import RVR
from bayes_fdi.rvm.sparse_bayes import SBLResult

__all__ = ["load"]


def load(path: str | os.PathLike[str], *, device: str | torch.device | None = None) -> Any:
    """Read a model written by :func:`bayes_fdi.rvm.persistence.save` (or ``model.save``).

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
    meta, arrays = read_model_file(path)
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
