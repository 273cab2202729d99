"""The campaign files shipped with bayes_fdi: in a source checkout and in an installed package.

The campaign TOML files live in the top-level ``sim/`` folder of the repository; the package
links it as ``bayes_fdi/data/campaigns`` (a symbolic link, so the files are not duplicated), and
building the package copies them in as package data. :func:`campaign_path` finds a shipped
campaign by name either way.
"""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path

__all__ = ["campaign_folder", "campaign_path", "shipped_campaigns"]


def campaign_folder() -> Path:
    return Path(os.fspath(resources.files("bayes_fdi") / "data" / "campaigns"))


def shipped_campaigns() -> tuple[str, ...]:
    """Names of the shipped campaigns (file stems), sorted."""
    folder = campaign_folder()
    if not folder.is_dir():
        return ()
    return tuple(sorted(p.stem for p in folder.glob("*.toml")))


def campaign_path(name: str) -> Path:
    """The file of a shipped campaign, e.g. ``campaign_path("paper-simulated")``.

    Raises
    ------
    ValueError
        If no shipped campaign has that name (the message lists them).
    """
    path = campaign_folder() / f"{name}.toml"
    if not path.is_file():
        raise ValueError(
            f"no shipped campaign {name!r}; shipped: {', '.join(shipped_campaigns()) or 'none'}"
        )
    return path
