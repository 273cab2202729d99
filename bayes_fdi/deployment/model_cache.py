"""Where the default model is cached, and under which name.

`bayes_fdi.deployment.fitting.default_model` fits the default model on first use and keeps it
in :func:`cache_dir`: ``$BAYES_FDI_CACHE`` if set, else the platform's user cache folder
(``$XDG_CACHE_HOME/bayes_fdi`` or ``~/.cache/bayes_fdi`` on Linux). Its file name
(:func:`default_model_path`) holds the package version, the model file format, the default
training's name and a fingerprint of the shipped training campaign files
(:func:`training_fingerprint`), so that an upgrade, or a changed training, fits a new one.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

from bayes_fdi import model_files

__all__ = [
    "CACHE_ENV",
    "DEFAULT_TRAININGS",
    "SMALL_ENV",
    "cache_dir",
    "default_model_path",
    "small_settings",
    "training_fingerprint",
]

#: The trainings of ``bayes-fdi fit --default --training``, the default first (those of
#: `bayes_fdi.default_diagnoser`, named here so that the command line starts without it).
DEFAULT_TRAININGS = ("excitation-mix", "dgen")
#: Environment variable naming the cache folder of the default model.
CACHE_ENV = "BAYES_FDI_CACHE"
#: Environment variable asking for the small (quick) settings, as the notebooks use.
SMALL_ENV = "BAYES_FDI_SMALL"


def cache_dir() -> Path:
    """The folder of the cached default model (created when the model is first written)."""
    folder = os.environ.get(CACHE_ENV)
    if folder:
        return Path(folder)
    from platformdirs import user_cache_dir

    return Path(user_cache_dir("bayes_fdi", appauthor=False))


def small_settings() -> bool:
    """Whether ``$BAYES_FDI_SMALL`` asks for the small (quick) settings."""
    return os.environ.get(SMALL_ENV, "") not in ("", "0")


def training_fingerprint() -> str:
    """The first 8 hex digits of the SHA-256 of the shipped training campaigns (the
    ``online-*.toml`` files: their names and contents), so that a changed training is never
    answered by a model cached from the old one."""
    from bayes_fdi.campaigns.shipped import campaign_folder

    digest = hashlib.sha256()
    for path in sorted(campaign_folder().glob("online-*.toml")):
        digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()[:8]


def default_model_path(*, small: bool | None = None) -> Path:
    """Where the default model is cached (``small``: the quick settings of the notebooks).

    The name holds the package version, the model file format, the training and the
    `training_fingerprint`.
    """
    from bayes_fdi import __version__

    small = small_settings() if small is None else small
    training, suffix = DEFAULT_TRAININGS[0], "-small" if small else ""
    name = (
        f"online-diagnoser-{__version__}-f{model_files.FORMAT_VERSION}-{training}-"
        f"{training_fingerprint()}{suffix}.npz"
    )
    return cache_dir() / name
