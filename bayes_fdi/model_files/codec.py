"""The object tree of a model file: a fitted object encoded as JSON plus numpy arrays, and back.

`ModelEncoder` turns an object of a persistable class (`bayes_fdi.model_files.registry`) and
everything it holds into JSON values and a table of arrays; `ModelDecoder` rebuilds the objects
from that JSON, reading the arrays from the open model file as it meets them. The encoding of
each kind of value is the table in the docstring of `bayes_fdi.model_files.format`, which
writes and reads the files.
"""

from __future__ import annotations

import enum
import math
import zipfile
from typing import Any

import numpy as np

from bayes_fdi.model_files.registry import is_namedtuple, resolve_class, stable_name

__all__ = ["MAX_DEPTH", "ModelDecoder", "ModelEncoder"]

#: Deepest nesting of values a file may hold (a fitted diagnoser nests about 20 levels).
MAX_DEPTH = 200


# ----------------------------------------------------------------------------------------------
# encoding
# ----------------------------------------------------------------------------------------------
class ModelEncoder:
    """Encodes object trees (`encode`); the arrays it meets are collected in ``arrays``."""

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
            name = stable_name(type(value))
            if name is None:
                raise ValueError(
                    f"{where}: enums of type {type(value).__qualname__} cannot be saved"
                )
            return {"__enum__": name, "value": self.encode(value.value, where)}
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
        name = stable_name(cls)
        if name is None:
            raise ValueError(
                f"{where}: objects of type {cls.__module__}.{cls.__qualname__} cannot be saved "
                "(not a registered class; see bayes_fdi.model_files.registry)"
            )
        self._remember(value)
        if is_namedtuple(cls):
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
class ModelDecoder:
    """Rebuilds an object tree from its JSON (`decode`), reading the arrays from ``archive``."""

    def __init__(
        self,
        archive: zipfile.ZipFile,
        specs: dict,
        source: str,
        device: Any,
        format_version: int,
        current_version: int,
    ) -> None:
        self.archive = archive
        self.specs = specs
        self.source = source
        self.device = device
        self.format_version = format_version
        self.current_version = current_version
        self.refs: list[Any] = []
        self.depth = 0

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
        self.depth += 1
        try:
            if self.depth > MAX_DEPTH:
                raise self._fail(f"values nested deeper than {MAX_DEPTH} levels")
            if isinstance(node, list):
                return [self.decode(v) for v in node]
            if not isinstance(node, dict) or len(node) == 0:
                raise self._fail(f"unexpected JSON value {node!r:.80}")
            tag = next(iter(node))
            handler = _HANDLERS.get(tag)
            if handler is None:
                raise self._fail(f"unknown tag {tag!r}")
            return handler(self, node)
        finally:
            self.depth -= 1

    def _upgraded(self, cls: type, data: dict) -> dict:
        """``data`` (an object's state or a named tuple's fields) in today's layout: a class
        whose saved layout changed defines ``upgrade_model_file(data, format_version)``."""
        upgrade = getattr(cls, "upgrade_model_file", None)
        if upgrade is None or self.format_version >= self.current_version:
            return data
        return upgrade(data, self.format_version)

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
        cls = resolve_class(node["__enum__"], self.source)
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
        cls = resolve_class(node["__namedtuple__"], self.source)
        slot = len(self.refs)
        self.refs.append(None)
        fields = self.decode(node["fields"])
        if isinstance(fields, dict):
            fields = self._upgraded(cls, fields)
        if not isinstance(fields, dict) or set(fields) != set(cls._fields):
            raise self._fail(f"fields of {node['__namedtuple__']} do not match the class")
        value = cls(**fields)
        self.refs[slot] = value
        return value

    def _object(self, node: dict) -> Any:
        cls = resolve_class(node["__object__"], self.source)
        value = cls.__new__(cls)
        self.refs.append(value)
        state = node.get("state")
        if not isinstance(state, dict):
            raise self._fail(f"object {node['__object__']} has no state")
        decoded = {str(k): self.decode(v) for k, v in state.items()}
        value.__dict__.update(self._upgraded(cls, decoded))
        check = getattr(cls, "check_model_file", None)
        if check is not None:  # the class refuses fitted values that cannot be right
            check(value)
        return value


#: JSON tag -> decoding method.
_HANDLERS = {
    "__float__": ModelDecoder._float,
    "__scalar__": ModelDecoder._scalar,
    "__ref__": ModelDecoder._ref,
    "__array__": ModelDecoder._array_node,
    "__object_array__": ModelDecoder._object_array,
    "__tensor__": ModelDecoder._tensor,
    "__torch_dtype__": ModelDecoder._torch_dtype,
    "__torch_device__": ModelDecoder._torch_device,
    "__enum__": ModelDecoder._enum,
    "__tuple__": ModelDecoder._tuple,
    "__set__": ModelDecoder._set,
    "__dict__": ModelDecoder._dict,
    "__items__": ModelDecoder._items,
    "__kdtree__": ModelDecoder._kdtree,
    "__namedtuple__": ModelDecoder._namedtuple,
    "__object__": ModelDecoder._object,
}
