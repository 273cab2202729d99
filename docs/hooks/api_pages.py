"""MkDocs hook: the API reference, one page per public face of ``bayes_fdi``, generated.

A *public face* is a package whose ``__init__`` declares ``__all__`` (``bayes_fdi.diagnosis``,
``bayes_fdi.rvm``, ...): its page ``api/<package>.md`` renders exactly the names of ``__all__``
with mkdocstrings, inherited members included, so the reference shows what a user imports and
not the modules behind it. ``api/index.md`` lists every face with its one-line summary. The pages
are generated at build time from the source tree, so a new face has its page without anyone
writing it.
"""

from __future__ import annotations

import ast
from pathlib import Path

from mkdocs.structure.files import File
from mkdocs.structure.nav import Section
from mkdocs.structure.pages import Page

_ROOT = Path(__file__).resolve().parents[2]
_PACKAGE = "bayes_fdi"


def _face(init: Path) -> tuple[str, list[str]] | None:
    """The summary line and ``__all__`` of a package's ``__init__``, or None without one."""
    tree = ast.parse(init.read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets
        ):
            names = [e.value for e in node.value.elts if isinstance(e, ast.Constant)]
            doc = (ast.get_docstring(tree) or "").strip().splitlines()
            return (doc[0] if doc else ""), names
    return None


def public_faces() -> dict[str, tuple[str, list[str]]]:
    """``{package: (summary, names)}`` of the packages that declare ``__all__``."""
    out = {}
    for init in sorted((_ROOT / _PACKAGE).rglob("__init__.py")):
        parts = init.parent.relative_to(_ROOT).parts
        if any(p.startswith("_") for p in parts):
            continue
        face = _face(init)
        if face is not None and face[1] and ".".join(parts) != _PACKAGE:
            out[".".join(parts)] = face
    return out


def _uri(package: str) -> str:
    return f"api/{package}.md"


def _page(package: str, summary: str, names: list[str]) -> str:
    members = "\n".join(f"        - {name}" for name in names)
    return (
        f"# `{package}`\n\n{summary}\n\n"
        f"::: {package}\n"
        "    options:\n"
        "      show_root_heading: false\n"
        "      show_root_toc_entry: false\n"
        "      inherited_members: true\n"
        "      show_submodules: false\n"
        f"      members:\n{members}\n"
    )


def on_files(files, config):
    """Add the generated pages."""
    faces = public_faces()
    for package, (summary, names) in faces.items():
        files.append(File.generated(config, _uri(package), content=_page(package, summary, names)))
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
    lines += [f"| [`{p}`]({p}.md) | {summary} |" for p, (summary, _) in faces.items()]
    files.append(File.generated(config, "api/index.md", content="\n".join(lines) + "\n"))
    return files


def on_nav(nav, config, files):
    """Append the "API reference" section: the overview, then one page per public face."""
    children = [Page("Overview", files.get_file_from_path("api/index.md"), config)]
    children += [
        Page(package, files.get_file_from_path(_uri(package)), config)
        for package in public_faces()
    ]
    nav.items.append(Section("API reference", children))
    return nav
