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
  torch at save time), ``root_class`` (the stable name of the saved object's class), ``arrays``
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
object of a persistable class       ``{"__object__": "StableName", "state": {attr: value}}``
                                    (its ``__dict__``: parameters and fitted attributes)
named tuple                         ``{"__namedtuple__": "StableName", "fields": {..}}``
enumeration member                  ``{"__enum__": "StableName", "value": ...}``
scipy ``cKDTree``                   ``{"__kdtree__": {"data": .., "leafsize": ..}}`` (rebuilt)
an object or array seen before      ``{"__ref__": n}`` (the n-th object or array encoded), so
                                    objects shared inside the model stay shared after loading
==================================  ================================================================

Persistable classes: the classes of the registry (`bayes_fdi.model_files.registry`), each stored
under a stable name that does not change when the class moves inside the package: the
diagnosers and their parts (normal models, whitening filters, detectors, isolators, trees,
scalers, recalibrators, result tuples), the RVMs and their kernels, a few scikit-learn classes of
the baselines, and a plug-in's classes registered with `register_persistable` in the running
process. A saved object's state is its ``__dict__`` (constructor parameters and fitted
attributes). A file naming any other class is refused, and loading imports only the modules the
registry names, never one named by a file. Objects holding something else (a user-supplied
callable kernel, a ``numpy.random.Generator`` as ``random_state``) cannot be saved: `save` raises
a `ValueError` naming the attribute.

Across releases: files of format version 1 (bayes_fdi 0.1.0) named classes by ``module:QualName``
and load through the registry's table of those names; a class whose saved layout has changed
since defines ``upgrade_model_file(data, format_version)``, which the loader calls on the saved
state (or fields) of a file of an older version.

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

This module writes and reads the files; the encoding of the object tree is
`bayes_fdi.model_files.codec` and the classes a file may hold `bayes_fdi.model_files.registry`
(`register_persistable` is importable from here too).
"""

from __future__ import annotations

import json
import math
import os
import re
import warnings
import zipfile
from typing import Any

import numpy as np

from bayes_fdi.atomic import atomic_path
from bayes_fdi.model_files.codec import ModelDecoder, ModelEncoder
from bayes_fdi.model_files.registry import resolve_class, stable_name

__all__ = [
    "DEFAULT_MAX_BYTES",
    "FORMAT_NAME",
    "FORMAT_VERSION",
    "MAX_METADATA_BYTES",
    "load",
    "read_metadata",
    "save",
]

FORMAT_NAME = "bayes_fdi.model"
#: 17: the online diagnoser's input envelope also judges a detection by the command during it
#: (``command_check``; older files load without that check, the stream they gave);
#: 16: the online diagnoser records how its isolability groups are found (``group_rule``; older
#: files load with their isolator's rule, the pairwise one unless commissioned; the default
#: model's groups now come from how its validation runs' seconds are named);
#: 15: group probabilities may be recalibrated by one temperature per age bin of the signature
#: (`~bayes_fdi.calibration.AgeTemperatureScaler`, which older readers do not know; the default
#: model's recalibration);
#: 14: the online diagnoser's stream state holds its fit proof (``proof``, a `FitProofState`) and
#: the diagnoser its ``fit_proof_seconds`` (older files load with 0: every detection proven, the
#: stream they gave);
#: 13: the online diagnoser may detect with `~bayes_fdi.diagnosis.detection.VarianceHoldCUSUM`
#: (the CUSUM whose alarm holds while the innovations' variance stays high, and its state, which
#: older readers do not know);
#: 12: the dynamic normal models' flow model may learn F minus the valve law's flow and their
#: std factors may follow the input novelty (``law_as_mean``, ``std_bins``: three more fields of
#: their compiled predictor's parameters, the novelty's reference rows and columns);
#: 11: the dynamic normal models' command lag may limit the stem's speed and the position model
#: may learn X minus the lagged command (``lag_speed_limits``, ``lag_as_mean``: two more fields
#: of their compiled predictor's parameters);
#: 10: a fault isolator records how its isolability groups were found (``group_rule``; older
#: files found them by the pairwise rule);
#: 9: the dynamic normal models may take physics inputs (``physics_inputs``: the command's lag
#: and the valve law, two more fields of their compiled predictor's parameters);
#: 8: the online diagnoser's input envelope judges a detection by the inputs before its
#: estimated change point (``change_lookback``, its state's ring of input averages);
#: 7: commissioned diagnosers detect with the two-speed CUSUM (``TwoSpeedCUSUM`` and its state,
#: which older readers do not know); 6: group probabilities may be recalibrated by a
#: `~bayes_fdi.calibration.TopLabelScaler` (older files load with their temperature scaling);
#: 5: the online diagnoser's input envelope checks the inputs' rates (its state holds them);
#: 4: the detection decision's hold (``hold``, the state's ``quiet`` count); 3: the online
#: diagnoser's components own their states; 2: classes named by their stable registered names;
#: 1 (bayes_fdi 0.1.0): classes named by ``module:QualName``.
FORMAT_VERSION = 17
#: Largest uncompressed size (bytes) of all members together that `load` accepts by default.
DEFAULT_MAX_BYTES = 4 * 2**30
#: Largest uncompressed size of the JSON metadata member.
MAX_METADATA_BYTES = 64 * 2**20
_MEMBER = re.compile(r"^a(\d+)\.npy$")
_LIBRARIES = ("numpy", "scipy", "scikit-learn", "torch")


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
    encoder = ModelEncoder()
    root = encoder.encode(obj, type(obj).__name__)
    if not isinstance(root, dict) or not ("__object__" in root or "__namedtuple__" in root):
        raise ValueError(f"can only save objects of persistable classes, got {type(obj).__name__}")
    meta = {
        "format": FORMAT_NAME,
        "format_version": FORMAT_VERSION,
        "bayes_fdi_version": _bayes_fdi_version(),
        "library_versions": _versions(),
        "root_class": stable_name(type(obj)),
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
        except RecursionError:
            raise ValueError(f"{source} is corrupt: metadata nested too deeply to read") from None
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
        root_class = resolve_class(meta.get("root_class"), source)
        if expected is not None and not issubclass(root_class, expected):
            names = expected if isinstance(expected, tuple) else (expected,)
            raise ValueError(
                f"{source} holds a {root_class.__qualname__}, not a "
                f"{' or '.join(c.__qualname__ for c in names)}"
            )
        _warn_versions(meta, source)
        decoder = ModelDecoder(
            archive, meta["arrays"], source, device, meta["format_version"], FORMAT_VERSION
        )
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
