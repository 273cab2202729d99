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
  ``dtype``, ``bayes_fdi_version``, (version 2) ``x_scale``, ``t_scale`` and (RVR, written
  since the polish was added; absent means none) ``polish``: null or ``gain``,
  ``restart_log_evidence``, ``pool_size``.
* ``X_fit`` -- the training inputs divided by ``x_scale`` (the candidate basis; relevance
  vectors are rows of it).
* per binary model ``k`` (one for RVR and binary RVC, one per class for one-vs-rest):
  ``m{k}_active`` (active candidate-basis indices, bias = 0 when ``bias``), ``m{k}_mean``,
  ``m{k}_covariance``, ``m{k}_alpha``, ``m{k}_evidence_trace``; weights, covariance,
  precisions, ``beta`` and the evidence in the units of the targets divided by ``t_scale``.

``x_scale`` and ``t_scale`` are the powers of two by which the estimator rescaled the data (see
`bayes_fdi.rvm.base`); version-1 files have neither (both 1).
* ``classes`` -- RVC only: the class labels (numeric or string).

A round trip reproduces predictions exactly (the same float arrays feed the same code).
Files are written atomically (`bayes_fdi.atomic`: a temporary file renamed over the destination).
Reading checks the archive before decompressing anything: its members' declared sizes must add
up to at most ``max_bytes`` (default :data:`DEFAULT_MAX_BYTES`) and each member's array header
must match its size. Unreadable files, missing entries, inconsistent shapes, non-finite weights,
non-positive precisions and unknown formats or versions raise :class:`ValueError`.

Imports :mod:`bayes_fdi.atomic`, :mod:`~bayes_fdi.rvm.kernels` and the solvers' face
:mod:`bayes_fdi.rvm.sbl` (for :class:`~bayes_fdi.rvm.sbl.SBLResult`).
"""

from __future__ import annotations

import io
import json
import os
import zipfile
from typing import Any

import numpy as np

from bayes_fdi.atomic import atomic_path, check_output_path
from bayes_fdi.rvm.kernels import Kernel, kernel_from_dict
from bayes_fdi.rvm.sbl import SBLResult

__all__ = [
    "DEFAULT_MAX_BYTES",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "params_from_json",
    "read_model_file",
    "save",
]

FORMAT_NAME = "bayes_fdi.rvm"
FORMAT_VERSION = 2
#: Default limit of the uncompressed size of a model file (bytes) read by `read_model_file`.
DEFAULT_MAX_BYTES = 1 << 30
#: At most this many arrays in a model file (a 1000-class one-vs-rest model has 5002).
_MAX_MEMBERS = 100_000
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


def params_from_json(params: dict[str, Any]) -> dict[str, Any]:
    """The estimator parameters stored in a model file, with the kernel rebuilt from its dict
    (the inverse of the parameters' JSON form written by :func:`save`)."""
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
        Destination; ``.npz`` is appended if the name does not end in it (as numpy does). The
        file is written atomically.

    Raises
    ------
    ValueError
        If the model uses a callable kernel or has labels that are neither numbers nor strings,
        or ``path`` cannot be written (a folder, a missing or read-only folder), checked before
        writing.
    """
    from sklearn.utils.validation import check_is_fitted

    estimator = _estimator_name(model)
    check_is_fitted(model)
    final = os.fspath(path)
    if os.path.isdir(final):
        raise ValueError(f"model file {final!r} is a folder, not a file")
    if not final.endswith(".npz"):
        final += ".npz"
    check_output_path(final, what="model file")
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
        "x_scale": float(getattr(model, "_x_scale_", 1.0)),
        "t_scale": float(getattr(model, "_t_scale_", 1.0)),
        "bayes_fdi_version": _version(),
    }
    if estimator == "RVR":
        polish = getattr(model, "polish_", None)
        meta["polish"] = None if polish is None else polish._asdict()
    with atomic_path(final) as tmp, open(tmp, "wb") as handle:
        np.savez(handle, metadata=np.array(json.dumps(meta)), **arrays)


def _read_member(archive: zipfile.ZipFile, info: zipfile.ZipInfo) -> np.ndarray:
    """One ``.npy`` member, its header checked against its size before the data are read."""
    raw = archive.read(info)  # bounded: the declared sizes were checked against the limit
    handle = io.BytesIO(raw)
    version = np.lib.format.read_magic(handle)
    if version == (1, 0):
        shape, _, dtype = np.lib.format.read_array_header_1_0(handle)
    elif version == (2, 0):
        shape, _, dtype = np.lib.format.read_array_header_2_0(handle)
    else:
        raise ValueError(f"array {info.filename!r} has npy version {version}")
    if dtype.hasobject:
        raise ValueError(f"array {info.filename!r} holds Python objects (refused)")
    count = 1
    for n in shape:
        count *= int(n)
    if count * dtype.itemsize != len(raw) - handle.tell():
        raise ValueError(
            f"array {info.filename!r} declares shape {shape} of {dtype} but holds "
            f"{len(raw) - handle.tell()} bytes"
        )
    handle.seek(0)
    return np.lib.format.read_array(handle, allow_pickle=False)


def read_model_file(
    path: str | os.PathLike[str], *, max_bytes: int = DEFAULT_MAX_BYTES
) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """Read a model file's metadata and arrays, checking sizes before decompressing.

    Parameters
    ----------
    path
        The ``.npz`` file.
    max_bytes
        Largest total uncompressed size accepted (the members' declared sizes).

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If the file is not a readable model file of a known format version, or exceeds
        ``max_bytes``.
    """
    name = os.fspath(path)
    if not os.path.exists(name):
        raise FileNotFoundError(2, "model file does not exist", name)
    if os.path.isdir(name):
        raise ValueError(f"{name!r} is a folder, not an RVM file")
    try:
        archive = zipfile.ZipFile(name)
    except (OSError, zipfile.BadZipFile, EOFError, ValueError) as exc:
        raise ValueError(f"{name!r} is not a readable RVM file ({exc})") from exc
    with archive:
        infos = archive.infolist()
        if len(infos) > _MAX_MEMBERS:
            raise ValueError(f"{name!r} holds {len(infos)} arrays, more than {_MAX_MEMBERS}")
        total = sum(i.file_size for i in infos)
        if total > max_bytes:
            raise ValueError(
                f"{name!r} would decompress to {total} bytes, more than the limit "
                f"max_bytes={max_bytes}"
            )
        arrays = {}
        try:
            for info in infos:
                key = info.filename.removesuffix(".npy")
                if key == info.filename or key in arrays:
                    raise ValueError(f"unexpected archive member {info.filename!r}")
                arrays[key] = _read_member(archive, info)
        except (
            OSError, zipfile.BadZipFile, EOFError, KeyError, ValueError, NotImplementedError,
            RuntimeError,
        ) as exc:  # fmt: skip
            raise ValueError(f"{name!r} is not a readable RVM file ({exc})") from exc
    if "metadata" not in arrays:
        raise ValueError(f"{name!r} has no RVM metadata")
    meta_array = arrays.pop("metadata")
    if meta_array.dtype.kind != "U" or meta_array.ndim != 0:
        raise ValueError(f"{name!r} has corrupt metadata (not a JSON string)")
    try:
        meta = json.loads(str(meta_array))
    except (json.JSONDecodeError, RecursionError) as exc:
        raise ValueError(f"{name!r} has corrupt metadata ({type(exc).__name__})") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT_NAME:
        raise ValueError(f"{name!r} is not a {FORMAT_NAME} file")
    version = meta.get("format_version")
    if (
        isinstance(version, bool)
        or not isinstance(version, int)
        or not 1 <= version <= (FORMAT_VERSION)
    ):
        raise ValueError(
            f"{name!r} has format version {version!r}; this bayes_fdi reads "
            f"versions 1..{FORMAT_VERSION}"
        )
    return meta, arrays
