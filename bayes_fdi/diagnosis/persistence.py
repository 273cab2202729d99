"""Saving fitted diagnosers without pickle: a versioned ``.npz`` file of JSON and arrays.

`save` writes any fitted object built from *persistable* classes (the diagnosers, their normal
models, regressors, scalers, trees of RVCs or SVMs, SVM baselines, recalibrators) and `load`
reads it back; ``FaultDiagnoser.save(path)`` / ``FaultDiagnoser.load(path)`` call them. A round
trip gives the same arrays, numbers and strings, so every output is identical.

Written by hand: no maintained library in the dependencies saves scikit-learn estimators holding
torch tensors without pickle (``joblib`` and ``torch.save`` pickle; ``skops`` knows neither torch
nor our estimators). The file is an ordinary zip archive of ``.npy`` members written by
``numpy.savez_compressed``; reading never unpickles (``allow_pickle=False``) and never runs code
named by the file.

File format (format name ``"bayes_fdi.model"``, :data:`FORMAT_VERSION`)
-----------------------------------------------------------------------
* ``metadata.npy`` -- a 0-d unicode array holding one JSON object: ``format``,
  ``format_version``, ``bayes_fdi_version``, ``library_versions`` (numpy, scipy, scikit-learn,
  torch at save time), ``root_class`` (``"module:QualName"`` of the saved object), ``arrays``
  (``{"a<k>": {"dtype": ..., "shape": [...]}}`` for every array member) and ``root``, the
  object tree encoded as below.
* ``a0.npy``, ``a1.npy``, ... -- the arrays (numeric, boolean or fixed-width unicode; never
  ``object``), compressed (deflate).

JSON encoding of a value (``root`` and everything it holds):

==================================  ================================================================
value                               JSON
==================================  ================================================================
``None``, bool, int, str            itself
finite float                        itself (shortest repr, exact); NaN / inf as
                                    ``{"__float__": "nan" | "inf" | "-inf"}``
list                                a JSON list
tuple                               ``{"__tuple__": [...]}``
set / frozenset                     ``{"__set__": [...], "frozen": bool}`` (sorted by repr)
dict with str keys                  ``{"__dict__": {key: value}}``
dict with other keys                ``{"__items__": [[key, value], ...]}``
numpy scalar                        ``{"__scalar__": dtype, "value": ...}``
numpy array                         ``{"__array__": "a<k>"}``; an object array of JSON values as
                                    ``{"__object_array__": [...], "shape": [...]}``
torch tensor                        ``{"__tensor__": "a<k>", "device": "cpu"}``
torch dtype                         ``{"__torch_dtype__": "float64"}``
torch device                        ``{"__torch_device__": "cpu"}``
object of a persistable class       ``{"__object__": "module:QualName", "state": {attr: value}}``
                                    (its ``__dict__``: parameters and fitted attributes)
named tuple                         ``{"__namedtuple__": "module:QualName", "fields": {..}}``
enumeration member                  ``{"__enum__": "module:QualName", "value": ...}``
scipy ``cKDTree``                   ``{"__kdtree__": {"data": .., "leafsize": ..}}`` (rebuilt)
an object or array seen before      ``{"__ref__": n}`` (the n-th object or array encoded), so
                                    objects shared inside the model stay shared after loading
==================================  ================================================================

Persistable classes: every class defined in the model layers (:data:`MODEL_PACKAGES`:
``bayes_fdi.rvm``, ``bayes_fdi.diagnosis``, ``bayes_fdi.calibration``: estimators, detectors,
kernels, scalers, recalibrators, result tuples), the estimators (``BaseEstimator`` subclasses)
and named tuples defined elsewhere in ``bayes_fdi``, the classes registered with
`register_persistable` (a plug-in's, registered in the running process) and the scikit-learn
classes of :data:`SKLEARN_CLASSES`. A saved object's state is its ``__dict__``
(constructor parameters and fitted attributes), so a new class needs nothing more than that.
A file naming any other class is refused. Objects holding something else (a user-supplied
callable kernel, a ``numpy.random.Generator`` as ``random_state``) cannot be saved: `save`
raises a `ValueError` naming the attribute.

Safety checks on reading, before anything is decompressed: the file must be a zip archive whose
members are exactly ``metadata.npy`` and the arrays the metadata lists; each member's
uncompressed size (from the archive's directory) and their total must not exceed ``max_bytes``
(default :data:`DEFAULT_MAX_BYTES`, 4 GiB) and the metadata not :data:`MAX_METADATA_BYTES`. A
corrupt file (bad zip, bad CRC, broken JSON, a missing or mis-shaped array), a foreign file
(another format, e.g. an RVM file of `bayes_fdi.rvm.save`) or a file of a newer format version
raises a `ValueError` that says which.

Tensors are loaded on the device they were saved from (``device=`` overrides, e.g. ``"cpu"`` for a
model fitted on a GPU). Files are written atomically: a temporary file in the destination folder,
flushed to disk, then renamed over the destination.
"""

from __future__ import annotations

import enum
import importlib
import json
import math
import os
import re
import warnings
import zipfile
from typing import Any

import numpy as np

from bayes_fdi.atomic import atomic_path

__all__ = [
    "DEFAULT_MAX_BYTES",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "MAX_METADATA_BYTES",
    "MODEL_PACKAGES",
    "SKLEARN_CLASSES",
    "load",
    "read_metadata",
    "register_persistable",
    "save",
]

FORMAT_NAME = "bayes_fdi.model"
FORMAT_VERSION = 1
#: Largest uncompressed size (bytes) of all members together that `load` accepts by default.
DEFAULT_MAX_BYTES = 4 * 2**30
#: Largest uncompressed size of the JSON metadata member.
MAX_METADATA_BYTES = 64 * 2**20
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
_MEMBER = re.compile(r"^a(\d+)\.npy$")
_LIBRARIES = ("numpy", "scipy", "scikit-learn", "torch")


def register_persistable(cls: type) -> type:
    """Allow instances of ``cls`` (a class with a ``__dict__``) in saved models; returns ``cls``.

    Usable as a class decorator. The classes of the model layers and the estimators and named
    tuples defined in ``bayes_fdi`` need no registration. A class defined elsewhere (a plug-in)
    must be registered in the process that saves and in the one that loads (its module is
    imported by the loader only because it was registered).
    """
    if not isinstance(cls, type):
        raise ValueError(f"register_persistable expects a class, got {cls!r}")
    _REGISTERED.add(_class_name(cls))
    return cls


def _class_name(cls: type) -> str:
    return f"{cls.__module__}:{cls.__qualname__}"


def _is_namedtuple(cls: type) -> bool:
    return issubclass(cls, tuple) and hasattr(cls, "_fields")


def _persistable(cls: type) -> bool:
    name = _class_name(cls)
    if name in SKLEARN_CLASSES or name in _REGISTERED:
        return True
    if cls.__module__.startswith(MODEL_PACKAGES):
        return True
    if not cls.__module__.startswith("bayes_fdi."):
        return False
    from sklearn.base import BaseEstimator

    return _is_namedtuple(cls) or issubclass(cls, BaseEstimator)


def _resolve_class(name: Any, source: str) -> type:
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
    if not isinstance(obj, type) or _class_name(obj) != name or not _persistable(obj):
        raise ValueError(f"{source}: class {name!r} is not allowed in a bayes_fdi model file")
    return obj


# ----------------------------------------------------------------------------------------------
# encoding
# ----------------------------------------------------------------------------------------------
class _Encoder:
    def __init__(self) -> None:
        self.arrays: dict[str, np.ndarray] = {}
        self.memo: dict[int, int] = {}  # id(object) -> reference number
        self.keep: list[Any] = []  # keeps memoised objects alive (ids stay unique)
        self.active: set[int] = set()

    def _remember(self, value: Any) -> None:
        self.memo[id(value)] = len(self.memo)
        self.keep.append(value)

    def _array(self, a: np.ndarray, where: str) -> str:
        if a.dtype.kind not in "biufcU" or a.dtype.hasobject:
            raise ValueError(f"{where}: arrays of dtype {a.dtype} cannot be saved")
        key = f"a{len(self.arrays)}"
        self.arrays[key] = a
        return key

    def encode(self, value: Any, where: str) -> Any:
        if isinstance(value, enum.Enum):  # before str/int: a StrEnum is a str
            cls = type(value)
            if not _persistable(cls):
                raise ValueError(f"{where}: enums of type {cls.__qualname__} cannot be saved")
            return {"__enum__": _class_name(cls), "value": self.encode(value.value, where)}
        if value is None or isinstance(value, bool | str):
            return value
        if isinstance(value, int) and type(value) is int:
            return value
        if type(value) is float:
            if math.isfinite(value):
                return value
            return {"__float__": "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf")}
        if isinstance(value, np.generic):
            if value.dtype.kind not in "biufU":
                raise ValueError(f"{where}: numpy scalars of dtype {value.dtype} cannot be saved")
            return {"__scalar__": value.dtype.str, "value": self.encode(value.item(), where)}
        if id(value) in self.memo:
            return {"__ref__": self.memo[id(value)]}
        if isinstance(value, np.ndarray):
            self._remember(value)
            if value.dtype.hasobject:
                items = [self.encode(v, f"{where}[...]") for v in value.ravel().tolist()]
                return {"__object_array__": items, "shape": list(value.shape)}
            return {"__array__": self._array(value, where)}
        torch_value = self._torch(value, where)
        if torch_value is not None:
            return torch_value
        if id(value) in self.active:
            raise ValueError(f"{where}: the object refers to itself (a cycle) and cannot be saved")
        self.active.add(id(value))
        try:
            return self._container_or_object(value, where)
        finally:
            self.active.discard(id(value))

    def _torch(self, value: Any, where: str) -> Any:
        import sys

        torch = sys.modules.get("torch")
        if torch is None:
            return None
        if isinstance(value, torch.Tensor):
            self._remember(value)
            array = value.detach().cpu().numpy()
            return {"__tensor__": self._array(array, where), "device": str(value.device)}
        if isinstance(value, torch.dtype):
            return {"__torch_dtype__": str(value).removeprefix("torch.")}
        if isinstance(value, torch.device):
            return {"__torch_device__": str(value)}
        return None

    def _container_or_object(self, value: Any, where: str) -> Any:
        cls = type(value)
        if cls is list:
            return [self.encode(v, f"{where}[{i}]") for i, v in enumerate(value)]
        if cls is tuple:
            return {"__tuple__": [self.encode(v, f"{where}[{i}]") for i, v in enumerate(value)]}
        if cls in (set, frozenset):
            items = sorted(value, key=repr)
            return {
                "__set__": [self.encode(v, f"{where}{{}}") for v in items],
                "frozen": cls is frozenset,
            }
        if cls is dict:
            if all(isinstance(k, str) for k in value):
                return {
                    "__dict__": {k: self.encode(v, f"{where}[{k!r}]") for k, v in value.items()}
                }
            return {
                "__items__": [
                    [self.encode(k, f"{where} key"), self.encode(v, f"{where}[{k!r}]")]
                    for k, v in value.items()
                ]
            }
        if _is_kdtree(value):
            self._remember(value)
            state = {"data": np.asarray(value.data), "leafsize": int(value.leafsize)}
            return {"__kdtree__": self.encode(state, f"{where}.tree")}
        if not _persistable(cls):
            raise ValueError(
                f"{where}: objects of type {cls.__module__}.{cls.__qualname__} cannot be saved "
                "(not a persistable class; see bayes_fdi.diagnosis.persistence)"
            )
        self._remember(value)
        name = _class_name(cls)
        if _is_namedtuple(cls):
            fields = {f: self.encode(getattr(value, f), f"{where}.{f}") for f in cls._fields}
            return {"__namedtuple__": name, "fields": {"__dict__": fields}}
        state = getattr(value, "__dict__", None)
        if state is None:
            raise ValueError(f"{where}: {cls.__qualname__} objects have no __dict__ to save")
        return {
            "__object__": name,
            "state": {k: self.encode(v, f"{where}.{k}") for k, v in state.items()},
        }


def _is_kdtree(value: Any) -> bool:
    import sys

    spatial = sys.modules.get("scipy.spatial")
    return spatial is not None and type(value) is spatial.cKDTree


# ----------------------------------------------------------------------------------------------
# decoding
# ----------------------------------------------------------------------------------------------
class _Decoder:
    def __init__(self, archive: zipfile.ZipFile, specs: dict, source: str, device: Any) -> None:
        self.archive = archive
        self.specs = specs
        self.source = source
        self.device = device
        self.refs: list[Any] = []

    def _fail(self, message: str) -> ValueError:
        return ValueError(f"{self.source} is corrupt: {message}")

    def _array(self, key: Any) -> np.ndarray:
        if not isinstance(key, str) or key not in self.specs:
            raise self._fail(f"reference to an unlisted array {key!r}")
        spec = self.specs[key]
        with self.archive.open(f"{key}.npy") as handle:
            array = np.lib.format.read_array(handle, allow_pickle=False)
        if array.dtype.str != spec["dtype"] or list(array.shape) != list(spec["shape"]):
            raise self._fail(
                f"array {key} is {array.dtype.str} {list(array.shape)}, the metadata says "
                f"{spec['dtype']} {list(spec['shape'])}"
            )
        return array

    def decode(self, node: Any) -> Any:
        if node is None or isinstance(node, bool | int | float | str):
            return node
        if isinstance(node, list):
            return [self.decode(v) for v in node]
        if not isinstance(node, dict) or len(node) == 0:
            raise self._fail(f"unexpected JSON value {node!r:.80}")
        tag = next(iter(node))
        handler = _HANDLERS.get(tag)
        if handler is None:
            raise self._fail(f"unknown tag {tag!r}")
        return handler(self, node)

    def _float(self, node: dict) -> float:
        return {"nan": math.nan, "inf": math.inf, "-inf": -math.inf}[node["__float__"]]

    def _scalar(self, node: dict) -> Any:
        return np.dtype(node["__scalar__"]).type(self.decode(node["value"]))

    def _ref(self, node: dict) -> Any:
        index = node["__ref__"]
        if not isinstance(index, int) or not 0 <= index < len(self.refs):
            raise self._fail(f"dangling reference {index!r}")
        return self.refs[index]

    def _array_node(self, node: dict) -> np.ndarray:
        array = self._array(node["__array__"])
        self.refs.append(array)
        return array

    def _object_array(self, node: dict) -> np.ndarray:
        items = node["__object_array__"]
        array = np.empty(len(items), dtype=object).reshape(tuple(node["shape"]))
        self.refs.append(array)
        array.reshape(-1)[:] = [self.decode(v) for v in items]
        return array

    def _tensor(self, node: dict) -> Any:
        import torch

        array = self._array(node["__tensor__"])
        device = torch.device(self.device if self.device is not None else node["device"])
        try:
            tensor = torch.from_numpy(array).to(device)
        except (RuntimeError, AssertionError) as exc:
            raise ValueError(
                f"{self.source}: a tensor was saved on device {node['device']!r}, which is not "
                f"available here ({exc}); pass device='cpu' to load it on the CPU"
            ) from None
        self.refs.append(tensor)
        return tensor

    def _torch_dtype(self, node: dict) -> Any:
        import torch

        dtype = getattr(torch, str(node["__torch_dtype__"]), None)
        if not isinstance(dtype, torch.dtype):
            raise self._fail(f"unknown torch dtype {node['__torch_dtype__']!r}")
        return dtype

    def _torch_device(self, node: dict) -> Any:
        import torch

        return torch.device(self.device if self.device is not None else node["__torch_device__"])

    def _enum(self, node: dict) -> Any:
        cls = _resolve_class(node["__enum__"], self.source)
        if not issubclass(cls, enum.Enum):
            raise self._fail(f"{node['__enum__']} is not an enumeration")
        return cls(self.decode(node["value"]))

    def _tuple(self, node: dict) -> tuple:
        return tuple(self.decode(v) for v in node["__tuple__"])

    def _set(self, node: dict) -> Any:
        items = [self.decode(v) for v in node["__set__"]]
        return frozenset(items) if node.get("frozen") else set(items)

    def _dict(self, node: dict) -> dict:
        return {str(k): self.decode(v) for k, v in node["__dict__"].items()}

    def _items(self, node: dict) -> dict:
        return {self.decode(k): self.decode(v) for k, v in node["__items__"]}

    def _kdtree(self, node: dict) -> Any:
        from scipy.spatial import cKDTree

        slot = len(self.refs)
        self.refs.append(None)
        state = self.decode(node["__kdtree__"])
        tree = cKDTree(state["data"], leafsize=int(state["leafsize"]))
        self.refs[slot] = tree
        return tree

    def _namedtuple(self, node: dict) -> Any:
        cls = _resolve_class(node["__namedtuple__"], self.source)
        slot = len(self.refs)
        self.refs.append(None)
        fields = self.decode(node["fields"])
        if not isinstance(fields, dict) or set(fields) != set(cls._fields):
            raise self._fail(f"fields of {node['__namedtuple__']} do not match the class")
        value = cls(**fields)
        self.refs[slot] = value
        return value

    def _object(self, node: dict) -> Any:
        cls = _resolve_class(node["__object__"], self.source)
        value = cls.__new__(cls)
        self.refs.append(value)
        state = node.get("state")
        if not isinstance(state, dict):
            raise self._fail(f"object {node['__object__']} has no state")
        value.__dict__.update({str(k): self.decode(v) for k, v in state.items()})
        return value


#: JSON tag -> decoding method.
_HANDLERS = {
    "__float__": _Decoder._float,
    "__scalar__": _Decoder._scalar,
    "__ref__": _Decoder._ref,
    "__array__": _Decoder._array_node,
    "__object_array__": _Decoder._object_array,
    "__tensor__": _Decoder._tensor,
    "__torch_dtype__": _Decoder._torch_dtype,
    "__torch_device__": _Decoder._torch_device,
    "__enum__": _Decoder._enum,
    "__tuple__": _Decoder._tuple,
    "__set__": _Decoder._set,
    "__dict__": _Decoder._dict,
    "__items__": _Decoder._items,
    "__kdtree__": _Decoder._kdtree,
    "__namedtuple__": _Decoder._namedtuple,
    "__object__": _Decoder._object,
}


# ----------------------------------------------------------------------------------------------
# files
# ----------------------------------------------------------------------------------------------
def _versions() -> dict[str, str]:
    from importlib.metadata import PackageNotFoundError, version

    out = {}
    for name in _LIBRARIES:
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            out[name] = "absent"
    return out


def _bayes_fdi_version() -> str:
    from bayes_fdi import __version__

    return __version__


def save(obj: Any, path: str | os.PathLike[str]) -> str:
    """Write a fitted object (e.g. a `FaultDiagnoser`) to ``path`` in the format above.

    Parameters
    ----------
    obj
        An object of a persistable class (see the module docstring).
    path
        Destination file, written exactly as named (``.npz`` is the usual suffix) and
        atomically.

    Returns
    -------
    str
        The path written.

    Raises
    ------
    ValueError
        If ``obj`` holds something that cannot be saved (the message names the attribute).
    """
    encoder = _Encoder()
    root = encoder.encode(obj, type(obj).__name__)
    if not isinstance(root, dict) or not ("__object__" in root or "__namedtuple__" in root):
        raise ValueError(f"can only save objects of persistable classes, got {type(obj).__name__}")
    meta = {
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "bayes_fdi_version": _bayes_fdi_version(),
        "library_versions": _versions(),
        "root_class": _class_name(type(obj)),
        "arrays": {
            k: {"dtype": a.dtype.str, "shape": list(a.shape)} for k, a in encoder.arrays.items()
        },
        "root": root,
    }
    text = json.dumps(meta, allow_nan=False, separators=(",", ":"))
    with atomic_path(path) as tmp, open(tmp, "wb") as handle:
        np.savez_compressed(handle, metadata=np.array(text), **encoder.arrays)
    return os.fspath(path)


def _open_checked(path: str | os.PathLike[str], max_bytes: int) -> tuple[zipfile.ZipFile, dict]:
    """Open the archive, check member names and sizes, read and check the metadata."""
    source = os.fspath(path)
    if not os.path.exists(source):
        raise FileNotFoundError(2, "no such model file", source)
    try:
        archive = zipfile.ZipFile(source)
    except (zipfile.BadZipFile, OSError) as exc:
        raise ValueError(
            f"{source} is not a bayes_fdi model file (not a zip archive: {exc})"
        ) from None
    try:
        infos = archive.infolist()
        names = [i.filename for i in infos]
        if "metadata.npy" not in names:
            raise ValueError(f"{source} is not a bayes_fdi model file (no metadata member)")
        total = 0
        for info in infos:
            total += info.file_size
            if info.filename == "metadata.npy" and info.file_size > MAX_METADATA_BYTES:
                raise ValueError(
                    f"{source}: metadata of {info.file_size} bytes exceeds the limit of "
                    f"{MAX_METADATA_BYTES} bytes; refusing to decompress it"
                )
        if total > max_bytes:
            raise ValueError(
                f"{source}: {total} bytes uncompressed exceed the limit of {max_bytes} bytes "
                "(max_bytes); refusing to decompress it"
            )
        try:
            with archive.open("metadata.npy") as handle:
                text = str(np.lib.format.read_array(handle, allow_pickle=False))
            meta = json.loads(text)
        except (ValueError, zipfile.BadZipFile, EOFError, OSError) as exc:
            raise ValueError(f"{source} is corrupt: unreadable metadata ({exc})") from None
        _check_header(meta, source)
        specs = meta.get("arrays")
        if not isinstance(specs, dict):
            raise ValueError(f"{source} is corrupt: no array table in the metadata")
        expected = {f"{k}.npy" for k in specs} | {"metadata.npy"}
        if set(names) != expected or len(names) != len(expected):
            odd = sorted(set(names) ^ expected)[:5]
            raise ValueError(f"{source} is corrupt: members do not match the metadata ({odd})")
        for key, spec in specs.items():
            if not _MEMBER.match(f"{key}.npy"):
                raise ValueError(f"{source} is corrupt: bad array name {key!r}")
            try:
                dtype = np.dtype(spec["dtype"])
                shape = [int(s) for s in spec["shape"]]
            except (KeyError, TypeError, ValueError):
                raise ValueError(f"{source} is corrupt: bad entry for array {key}") from None
            if dtype.hasobject or dtype.kind not in "biufcU" or min(shape, default=0) < 0:
                raise ValueError(f"{source} is corrupt: array {key} has dtype {dtype}")
            if archive.getinfo(f"{key}.npy").file_size < dtype.itemsize * math.prod(shape):
                raise ValueError(f"{source} is corrupt: array {key} is shorter than its shape")
    except BaseException:
        archive.close()
        raise
    return archive, meta


def _check_header(meta: Any, source: str) -> None:
    if not isinstance(meta, dict):
        raise ValueError(f"{source} is not a bayes_fdi model file")
    name = meta.get("format")
    if name != FORMAT_NAME:
        hint = ""
        if name == "bayes_fdi.rvm":
            hint = "; it is a single RVM: read it with bayes_fdi.rvm.load"
        raise ValueError(f"{source} is not a bayes_fdi model file (format {name!r}){hint}")
    version = meta.get("format_version")
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise ValueError(f"{source} is corrupt: format version {version!r}")
    if version > FORMAT_VERSION:
        raise ValueError(
            f"{source} has format version {version}, newer than this bayes_fdi "
            f"({_bayes_fdi_version()}) reads (1..{FORMAT_VERSION}); upgrade bayes_fdi "
            f"(the file was written by bayes_fdi {meta.get('bayes_fdi_version', '?')})"
        )


def read_metadata(path: str | os.PathLike[str], *, max_bytes: int = DEFAULT_MAX_BYTES) -> dict:
    """The checked metadata of a model file, without its ``root`` tree (nothing is rebuilt)."""
    archive, meta = _open_checked(path, max_bytes)
    archive.close()
    return {k: v for k, v in meta.items() if k != "root"}


def load(
    path: str | os.PathLike[str],
    *,
    expected: type | tuple[type, ...] | None = None,
    max_bytes: int = DEFAULT_MAX_BYTES,
    device: Any = None,
) -> Any:
    """Read an object written by `save`.

    Parameters
    ----------
    path
        The model file.
    expected
        Class (or classes) the saved object must be an instance of; a file holding anything
        else raises a `ValueError` naming what it holds.
    max_bytes
        Limit on the total uncompressed size of the file's members, checked before anything is
        decompressed.
    device
        Put every torch tensor on this device instead of the one it was saved from.

    Returns
    -------
    object
        The rebuilt object; its outputs equal those of the saved one exactly.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        For a corrupt, foreign or newer file, a file over ``max_bytes``, or an unexpected class.
    """
    archive, meta = _open_checked(path, max_bytes)
    source = os.fspath(path)
    try:
        root_class = _resolve_class(meta.get("root_class"), source)
        if expected is not None and not issubclass(root_class, expected):
            names = expected if isinstance(expected, tuple) else (expected,)
            raise ValueError(
                f"{source} holds a {root_class.__qualname__}, not a "
                f"{' or '.join(c.__qualname__ for c in names)}"
            )
        _warn_versions(meta, source)
        decoder = _Decoder(archive, meta["arrays"], source, device)
        try:
            obj = decoder.decode(meta.get("root"))
        except (KeyError, TypeError, IndexError, zipfile.BadZipFile, EOFError) as exc:
            raise ValueError(f"{source} is corrupt: {type(exc).__name__}: {exc}") from None
        except ValueError as exc:
            if str(exc).startswith(source):
                raise
            raise ValueError(f"{source} is corrupt: {exc}") from None
    finally:
        archive.close()
    if type(obj) is not root_class:
        raise ValueError(f"{source} is corrupt: the root object is not a {root_class.__qualname__}")
    return obj


def _warn_versions(meta: dict, source: str) -> None:
    saved = meta.get("library_versions")
    if not isinstance(saved, dict):
        return
    now = _versions()
    if saved.get("scikit-learn") not in (None, now["scikit-learn"]):
        warnings.warn(
            f"{source} was saved with scikit-learn {saved.get('scikit-learn')}, this is "
            f"{now['scikit-learn']}: scikit-learn's fitted attributes may differ between versions",
            UserWarning,
            stacklevel=3,
        )
