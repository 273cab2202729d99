"""MkDocs hook: one API reference page per public module of ``bayes_fdi``, generated.

Every module under ``bayes_fdi/`` whose dotted name has no part starting with ``_`` gets a page
``api/<module>.md`` holding ``::: <module>`` (mkdocstrings renders its docstrings), and the nav
gets an "API reference" section with one sub-section per subpackage. The pages are generated at
build time from the source tree, so a new module has its page without anyone writing it.
"""

from __future__ import annotations

from pathlib import Path

from mkdocs.structure.files import File
from mkdocs.structure.nav import Section
from mkdocs.structure.pages import Page

_ROOT = Path(__file__).resolve().parents[2]
_PACKAGE = "bayes_fdi"


def public_modules() -> list[str]:
    """Dotted names of the public modules, packages first within each folder."""
    names = []
    for path in sorted((_ROOT / _PACKAGE).rglob("*.py")):
        parts = list(path.relative_to(_ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        if any(p.startswith("_") for p in parts):
            continue
        names.append(".".join(parts))
    return sorted(names, key=lambda n: (n.split(".")[:2], n.count(".") > 1, n))


def _uri(module: str) -> str:
    return f"api/{module}.md"


def on_files(files, config):
    """Add the generated pages."""
    modules = public_modules()
    for module in modules:
        text = f"# `{module}`\n\n::: {module}\n    options:\n      show_root_heading: false\n"
        files.append(File.generated(config, _uri(module), content=text))
    lines = ["# API reference", "", "One page per public module of `bayes_fdi`.", ""]
    for module in modules:
        indent = "    " * max(0, module.count(".") - 1)
        lines.append(f"{indent}- [`{module}`]({module}.md)")
    files.append(File.generated(config, "api/index.md", content="\n".join(lines) + "\n"))
    return files


def on_nav(nav, config, files):
    """Append the "API reference" section: the index, then one sub-section per subpackage."""
    groups: dict[str, list] = {}
    for module in public_modules():
        key = ".".join(module.split(".")[:2])
        groups.setdefault(key, []).append(module)
    children = [Page("Overview", files.get_file_from_path("api/index.md"), config)]
    for key, modules in groups.items():
        pages = [Page(m, files.get_file_from_path(_uri(m)), config) for m in modules]
        children.append(pages[0] if len(pages) == 1 else Section(key, pages))
    section = Section("API reference", children)
    nav.items.append(section)
    return nav
