"""Loading fitted RVMs written by `bayes_fdi.rvm.persistence.save` (``RVR.save``, ``RVC.save``).

The file format is described in `bayes_fdi.rvm.persistence`. Every field is checked before the
estimator is rebuilt: types, shapes, indices, finiteness of the arrays, positive precisions and
noise precision. Whatever is wrong with a file, the error is a :class:`ValueError` naming it.

Imports the estimators, :mod:`~bayes_fdi.rvm.persistence` and the solvers' face
:mod:`bayes_fdi.rvm.sbl`.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from numbers import Real
from typing import Any, NamedTuple

import numpy as np
import torch

from bayes_fdi.rvm.classification import RVC
from bayes_fdi.rvm.persistence import DEFAULT_MAX_BYTES, params_from_json, read_model_file
from bayes_fdi.rvm.regression import RVR
from bayes_fdi.rvm.sbl import Polish, SBLResult

__all__ = ["load"]

_DTYPES = {"float64": torch.float64, "float32": torch.float32}
#: Errors a malformed field can raise while the estimator is rebuilt (all become ValueError).
_MALFORMED = (
    TypeError, KeyError, IndexError, AttributeError, RecursionError, OverflowError,
    AssertionError, RuntimeError,
)  # fmt: skip


def _positive(value: Any, what: str, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, Real) or not math.isfinite(value):
        raise ValueError(f"{name!r}: {what} must be a finite number, got {value!r}")
    if value <= 0:
        raise ValueError(f"{name!r}: {what} must be > 0, got {value!r}")
    return float(value)


def _float_array(array: np.ndarray, what: str, name: str) -> np.ndarray:
    if array.dtype.kind != "f":
        raise ValueError(f"{name!r}: {what} must hold floats, got dtype {array.dtype}")
    if not np.all(np.isfinite(array)):
        raise ValueError(f"{name!r}: {what} contains NaN or infinity")
    return array


def _polish(value: Any, name: str) -> Polish | None:
    """The ``polish`` record of an RVR file (None when absent or null), validated."""
    if value is None:
        return None
    if not isinstance(value, dict) or set(value) != set(Polish._fields):
        raise ValueError(f"{name!r}: polish must be null or a table of {Polish._fields}")
    gain, restart, pool = value["gain"], value["restart_log_evidence"], value["pool_size"]
    for what, v in (("gain", gain), ("restart_log_evidence", restart)):
        if isinstance(v, bool) or not isinstance(v, Real) or not math.isfinite(v):
            raise ValueError(f"{name!r}: polish {what} must be a finite number, got {v!r}")
    if gain < 0:
        raise ValueError(f"{name!r}: polish gain must be >= 0, got {gain!r}")
    if isinstance(pool, bool) or not isinstance(pool, int) or pool < 1:
        raise ValueError(f"{name!r}: polish pool_size must be a positive integer, got {pool!r}")
    return Polish(gain=float(gain), restart_log_evidence=float(restart), pool_size=pool)


def load(
    path: str | os.PathLike[str],
    *,
    device: str | torch.device | None = None,
    max_bytes: int = DEFAULT_MAX_BYTES,
) -> Any:
    """Read a model written by :func:`bayes_fdi.rvm.persistence.save` (or ``model.save``).

    Parameters
    ----------
    path : str or path-like
        The ``.npz`` file.
    device : str or torch.device, optional
        Where to put the model's tensors (default: CPU, or the saved ``device`` parameter).
    max_bytes : int, default 2**30
        Refuse files whose arrays would decompress to more than this many bytes (checked
        before anything is decompressed).

    Returns
    -------
    RVR or RVC
        The fitted estimator; its predictions equal the saved model's exactly.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If the file is corrupt, too large, of another format or version, or internally
        inconsistent (shapes, indices, non-finite weights, non-positive precisions).
    """
    meta, arrays = read_model_file(path, max_bytes=max_bytes)
    name = os.fspath(path)
    try:
        return _rebuild(meta, arrays, name, device)
    except _MALFORMED as exc:
        raise ValueError(f"{name!r} has malformed content ({type(exc).__name__}: {exc})") from None


class _Header(NamedTuple):
    """A model file's metadata and training inputs, validated (:func:`_header`)."""

    cls: type
    params: dict[str, Any]
    models_meta: list[Any]
    width: float | None
    n_features: int
    dtype: torch.dtype
    X_fit: np.ndarray
    x_scale: float
    t_scale: float


def _header(meta: dict, arrays: dict, name: str) -> _Header:
    """The estimator class, parameters, scales and training inputs a file declares."""
    try:
        cls = {"RVR": RVR, "RVC": RVC}[meta["estimator"]]
        if not isinstance(meta["params"], dict):
            raise TypeError("params is not a table")
        params = params_from_json(meta["params"])
        models_meta = list(meta["models"])
        width = meta["width"]
        n_features = meta["n_features_in"]
        dtype = _DTYPES[meta["dtype"]]
        X_fit_np = arrays["X_fit"]
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"{name!r} has incomplete or invalid metadata ({exc!r})") from exc
    if isinstance(n_features, bool) or not isinstance(n_features, int) or n_features < 1:
        raise ValueError(f"{name!r}: n_features_in must be a positive integer, got {n_features!r}")
    if width is not None:
        width = _positive(width, "width", name)
    x_scale = _positive(meta.get("x_scale", 1.0), "x_scale", name)
    t_scale = _positive(meta.get("t_scale", 1.0), "t_scale", name)
    if cls is RVR and len(models_meta) != 1:
        raise ValueError(f"{name!r}: an RVR file must hold exactly one model")
    if X_fit_np.ndim != 2 or X_fit_np.shape[1] != n_features:
        raise ValueError(
            f"{name!r}: training inputs of shape {X_fit_np.shape} do not match metadata"
        )
    _float_array(X_fit_np, "X_fit", name)
    return _Header(cls, params, models_meta, width, n_features, dtype, X_fit_np, x_scale, t_scale)


def _rebuild(meta: dict, arrays: dict, name: str, device: Any) -> Any:
    head = _header(meta, arrays, name)
    params, width = head.params, head.width
    try:
        model = head.cls(**params)
        model._check_params()
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{name!r} has invalid estimator parameters ({exc})") from None
    dev = (
        torch.device(device) if device is not None else torch.device(params.get("device") or "cpu")
    )
    X_fit = torch.tensor(head.X_fit, dtype=head.dtype, device=dev)
    model.n_features_in_ = head.n_features
    is_rbf = model._is_plain_rbf()
    width_s = model._scaled_width(width, head.x_scale) if is_rbf else width
    kern = model._resolve_kernel(width_s, head.x_scale)
    if is_rbf and width is None:
        raise ValueError(f"{name!r}: an RBF model needs its width")
    n_basis = (1 if model.bias else 0) + (X_fit.shape[0] if kern is not None else head.n_features)

    def binary(k: int, target: Any) -> None:
        is_rvr = isinstance(target, RVR)
        result = _binary_result(arrays, head, k, n_basis, dev, name, needs_beta=is_rvr)
        scales = {"x_scale": head.x_scale, "t_scale": head.t_scale if is_rvr else 1.0}
        target._set_state(result, X_fit, kern, width, warn=False, **scales)
        if is_rvr:
            beta = result.beta
            target._beta_scaled_ = beta
            with np.errstate(under="ignore", over="ignore"):
                target.beta_ = float(np.float64(beta) / np.float64(head.t_scale) ** 2)

    if head.cls is RVR:
        binary(0, model)
        model.polish_ = _polish(meta.get("polish"), name)
        return model
    return _rebuild_classifier(model, arrays, head, X_fit, binary, name)


def _binary_result(
    arrays: dict,
    head: _Header,
    k: int,
    n_basis: int,
    dev: torch.device,
    name: str,
    *,
    needs_beta: bool,
) -> SBLResult:
    """The fitted state of binary model ``k`` of a file (validated)."""
    try:
        active = arrays[f"m{k}_active"]
        mean = arrays[f"m{k}_mean"]
        cov = arrays[f"m{k}_covariance"]
        alpha = arrays[f"m{k}_alpha"]
        trace = arrays[f"m{k}_evidence_trace"]
        info = head.models_meta[k]
    except (KeyError, IndexError) as exc:
        raise ValueError(f"{name!r} is missing model {k} ({exc!r})") from exc
    if not isinstance(info, dict):
        raise ValueError(f"{name!r}: the metadata of model {k} is not a table")
    m = len(active) if active.ndim == 1 else -1
    if (
        active.dtype.kind not in "iu"
        or active.ndim != 1
        or mean.shape != (m,)
        or alpha.shape != (m,)
        or cov.shape != (m, m)
        or trace.ndim != 1
        or (m and (active.min() < 0 or active.max() >= n_basis))
        or np.unique(active).size != m
    ):
        raise ValueError(f"{name!r}: arrays of model {k} have inconsistent shapes or indices")
    what = f"model {k}"
    _float_array(mean, f"the weights of {what}", name)
    _float_array(cov, f"the covariance of {what}", name)
    _float_array(alpha, f"the precisions of {what}", name)
    if np.any(alpha <= 0):
        raise ValueError(f"{name!r}: the precisions (alpha) of {what} must be > 0")
    if np.any(np.diagonal(cov) < 0):
        raise ValueError(f"{name!r}: the covariance of {what} has negative variances")
    if trace.dtype.kind != "f":
        raise ValueError(f"{name!r}: the evidence trace of {what} must hold floats")
    beta = info.get("beta")
    if beta is not None:
        beta = _positive(beta, f"the noise precision (beta) of {what}", name)
    log_evidence = info["log_evidence"]
    if isinstance(log_evidence, bool) or not isinstance(log_evidence, Real):
        raise ValueError(f"{name!r}: log_evidence of {what} must be a number")
    n_iter, converged = info["n_iter"], info["converged"]
    if isinstance(n_iter, bool) or not isinstance(n_iter, int) or n_iter < 0:
        raise ValueError(f"{name!r}: n_iter of {what} must be an integer >= 0")
    if not isinstance(converged, bool):
        raise ValueError(f"{name!r}: converged of {what} must be true or false")
    if needs_beta and beta is None:
        raise ValueError(f"{name!r}: an RVR model needs a noise precision 'beta'")
    dtype = head.dtype
    return SBLResult(
        active=torch.tensor(active, dtype=torch.long, device=dev),
        mean=torch.tensor(mean, dtype=dtype, device=dev),
        covariance=torch.tensor(cov, dtype=dtype, device=dev),
        alpha=torch.tensor(alpha, dtype=dtype, device=dev),
        beta=float("nan") if beta is None else beta,
        evidence_trace=torch.tensor(trace, dtype=torch.float64),
        log_evidence=float(log_evidence),
        n_iter=n_iter,
        converged=converged,
    )


def _rebuild_classifier(
    model: RVC,
    arrays: dict,
    head: _Header,
    X_fit: torch.Tensor,
    binary: Callable[[int, Any], None],
    name: str,
) -> RVC:
    """The class labels and binary models of an RVC file (one, or one per class)."""
    if "classes" not in arrays:
        raise ValueError(f"{name!r}: an RVC file must hold the class labels")
    classes = arrays["classes"]
    if classes.ndim != 1 or classes.dtype.kind not in "biufU":
        raise ValueError(f"{name!r}: the class labels must be a 1-D array of numbers or text")
    if np.unique(classes).size != classes.size:
        raise ValueError(f"{name!r}: the class labels repeat")
    model.classes_ = classes
    n_classes = len(model.classes_)
    expected = 1 if n_classes == 2 else n_classes
    n_models = len(head.models_meta)
    if n_classes < 2 or n_models != expected:
        raise ValueError(
            f"{name!r}: {n_classes} classes need {expected} binary models, found {n_models}"
        )
    if expected == 1:
        binary(0, model)
        model.estimators_ = None
        return model
    subs = []
    for k in range(expected):
        sub = RVC(**head.params)
        sub.classes_ = np.array([0, 1])
        sub.n_features_in_ = head.n_features
        binary(k, sub)
        sub.estimators_ = None
        subs.append(sub)
    model._adopt_one_vs_rest(subs, X_fit, head.width)
    return model
