"""MkDocs hook: the API reference, one page per public face of ``bayes_fdi``, generated.

A *public face* is a package whose ``__init__`` declares ``__all__`` (``bayes_fdi.diagnosis``,
``bayes_fdi.rvm``, ...): its page ``api/<package>.md`` renders the package's docstring, then each
name of ``__all__`` with mkdocstrings, inherited members included, so the reference shows what a
user imports and not the modules behind it. ``api/index.md`` lists every face with its one-line
summary. The pages are generated at build time from the source tree, so a new face has its page
without anyone writing it.

Each object is rendered once: a nested face (``bayes_fdi.diagnosis.online``) shows only the
names that its parent face (``bayes_fdi.diagnosis``) does not already export, and links the
others to the parent's page. Faces listed in ``INTERNAL_FACES`` get no page.

A name that is also the name of a submodule (``bayes_fdi.actuator.simulate``, the function, and
``bayes_fdi/actuator/simulate.py``) is rendered from the module it is defined in: griffe, like
mkdocstrings, gives the submodule precedence over the package's attribute of the same name, so
the name's heading and anchor are its full path (``bayes_fdi.actuator.simulate.simulate``).
"""

from __future__ import annotations

import ast
from pathlib import Path
from typing import NamedTuple

from mkdocs.structure.files import File
from mkdocs.structure.nav import Section
from mkdocs.structure.pages import Page

_ROOT = Path(__file__).resolve().parents[2]
_PACKAGE = "bayes_fdi"

# Packages that declare ``__all__`` for the modules of the library, not for its users.
INTERNAL_FACES = {
    # the solvers behind RVR and RVC and their numerics; users meet them through bayes_fdi.rvm
    "bayes_fdi.rvm.sbl",
}

# mkdocstrings options of every rendered name
_OPTIONS = {
    "show_root_heading": "true",
    "show_root_full_path": "false",
    "show_root_members_full_path": "false",
    "heading_level": "2",
    "inherited_members": "true",
    "show_submodules": "false",
    "show_symbol_type_heading": "true",
    "show_symbol_type_toc": "true",
    "separate_signature": "true",
}


class Face(NamedTuple):
    """A public face: its summary line, its names, and where each name is imported from."""

    summary: str
    names: list[str]
    origins: dict[str, str]  # name -> dotted path of the object it is imported as


def _origins(tree: ast.Module, package: str) -> dict[str, str]:
    """``{name: dotted path}`` of the names that ``from ... import`` binds in an ``__init__``."""
    out = {}
    for node in tree.body:
        if not isinstance(node, ast.ImportFrom):
            continue
        if node.level:
            base = package.rsplit(".", node.level - 1)[0] if node.level > 1 else package
            module = f"{base}.{node.module}" if node.module else base
        else:
            module = node.module or ""
        for alias in node.names:
            out[alias.asname or alias.name] = f"{module}.{alias.name}"
    return out


def _face(init: Path, package: str) -> Face | None:
    """The face declared by a package's ``__init__``, or None without ``__all__``."""
    tree = ast.parse(init.read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets
        ):
            names = [e.value for e in node.value.elts if isinstance(e, ast.Constant)]
            summary = " ".join((ast.get_docstring(tree) or "").strip().split("\n\n")[0].split())
            return Face(summary, names, _origins(tree, package))
    return None


def public_faces() -> dict[str, Face]:
    """``{package: face}`` of the packages that declare ``__all__``, internal ones left out."""
    out = {}
    for init in sorted((_ROOT / _PACKAGE).rglob("__init__.py")):
        parts = init.parent.relative_to(_ROOT).parts
        package = ".".join(parts)
        if any(p.startswith("_") for p in parts) or package in INTERNAL_FACES:
            continue
        face = _face(init, package)
        if face is not None and face.names and package != _PACKAGE:
            out[package] = face
    return out


def parent_face(package: str, faces: dict[str, Face]) -> str | None:
    """The nearest enclosing package of ``package`` that is a public face, or None."""
    parts = package.split(".")
    for end in range(len(parts) - 1, 1, -1):
        parent = ".".join(parts[:end])
        if parent in faces:
            return parent
    return None


def page_names(package: str, faces: dict[str, Face]) -> tuple[list[str], list[str]]:
    """The names rendered on ``package``'s page, and those left to its parent face's page."""
    parent = parent_face(package, faces)
    inherited = set(faces[parent].names) if parent else set()
    names = faces[package].names
    return [n for n in names if n not in inherited], [n for n in names if n in inherited]


def render_path(package: str, name: str, face: Face) -> str:
    """The dotted path mkdocstrings renders ``name`` from (see the module docstring)."""
    directory = _ROOT.joinpath(*package.split("."))
    shadowed = (directory / f"{name}.py").exists() or (directory / name / "__init__.py").exists()
    if shadowed and name in face.origins:
        return face.origins[name]
    return f"{package}.{name}"


def _block(path: str, options: dict[str, str]) -> str:
    lines = [f"::: {path}", "    options:"]
    lines += [f"      {key}: {value}" for key, value in options.items()]
    return "\n".join(lines) + "\n"


def _uri(package: str) -> str:
    return f"api/{package}.md"


def _page(package: str, faces: dict[str, Face]) -> str:
    face = faces[package]
    own, elsewhere = page_names(package, faces)
    parts = [f"# `{package}`\n"]
    parts.append(_block(package, {"show_root_heading": "false", "members": "false"}))
    if elsewhere:
        parent = parent_face(package, faces)
        links = ", ".join(
            f"[`{n}`]({parent}.md#{render_path(parent, n, faces[parent])})" for n in elsewhere
        )
        parts.append(f"Also exported here, documented with [`{parent}`]({parent}.md): {links}.\n")
    parts += [_block(render_path(package, name, face), _OPTIONS) for name in own]
    return "\n".join(parts)


def on_files(files, config):
    """Add the generated pages."""
    faces = public_faces()
    for package in faces:
        files.append(File.generated(config, _uri(package), content=_page(package, faces)))
    lines = [
        "# API reference",
        "",
        "What a user imports: the public names of each package (its `__init__`), with their "
        "inherited methods. The modules behind them are internal and may move; the names below "
        "do not.",
        "",
        "| package | what it holds |",
        "|---|---|",
    ]
    lines += [f"| [`{p}`]({p}.md) | {face.summary} |" for p, face in faces.items()]
    files.append(File.generated(config, "api/index.md", content="\n".join(lines) + "\n"))
    return files


def on_nav(nav, config, files):
    """Append the "API reference" section: the overview, then one page per public face."""
    children = [Page("Overview", files.get_file_from_path("api/index.md"), config)]
    children += [
        Page(package, files.get_file_from_path(_uri(package)), config) for package in public_faces()
    ]
    nav.items.append(Section("API reference", children))
    return nav
