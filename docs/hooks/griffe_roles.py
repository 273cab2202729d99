"""Griffe extension: the reStructuredText roles of the docstrings, rendered as the site renders.

The package's docstrings are numpy-style and read well in ``help()``; many use reST roles
(``:class:`~bayes_fdi.x.Y```, ``:func:`f```, ``:math:`\\alpha```), Sphinx's default role
(```~bayes_fdi.x.Y```) and ``.. math::`` blocks that Markdown would show literally. Once the
package is loaded, this extension rewrites every docstring in it:

- ``:class:``, ``:func:``, ``:meth:``, ``:mod:``, ``:data:``, ``:attr:``, ``:exc:``, ``:obj:``
  and ```~name``` -> a cross-reference to the name's entry in the API reference when the name
  is documented there (under the public path a user imports it from: ``docs/hooks/api_pages.py``
  decides what is documented), else inline code of the name. ``~`` keeps only the name's last
  part, as Sphinx shows it; without ``~`` a full path is shown as the public path, a relative
  name as written;
- ``:math:`x``` -> ``$x$`` and a ``.. math::`` block -> ``$$ ... $$``, which
  ``pymdownx.arithmatex`` and the ``mathml`` hook render as MathML.

Written by hand: the docstrings stay valid reST for ``help()``; no maintained griffe extension
converts reST roles inside numpy-style docstrings.
"""

from __future__ import annotations

import importlib.util
import re
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import griffe

_ROLE = re.compile(r":(?:py:)?(class|func|meth|mod|data|attr|exc|obj):`(~?)([^`]+)`")
_DEFAULT_ROLE = re.compile(r"(?<![`\w])`~([A-Za-z_][\w.]*)`(?!`)")
_MATH = re.compile(r":math:`([^`]+)`")
_MATH_BLOCK = re.compile(
    r"^(?P<indent>[ \t]*)\.\. math::[ \t]*\n"
    r"(?P<body>(?:[ \t]*\n|(?P=indent)[ \t]+.*\n)+)",
    re.M,
)

# A resolver: (target as written, docstring's object) -> public path documented, or None.
Resolver = Callable[[str, "griffe.Object | None"], "str | None"]


def _no_links(target: str, obj: griffe.Object | None) -> str | None:
    return None


def _reference(short: bool, target: str, obj: griffe.Object | None, resolve: Resolver) -> str:
    label = None
    if "<" in target and target.endswith(">"):  # :class:`text <target>`
        label, target = target[:-1].split("<", 1)
        label, target = label.strip(), target.strip()
    public = resolve(target, obj)
    if label is None:
        # a full path shows where the user imports the name from; a relative one, as written
        shown = public if public and target.startswith("bayes_fdi.") else target
        label = shown.rsplit(".", 1)[-1] if short else shown
    return f"[`{label}`][{public}]" if public else f"`{label}`"


def _math_block(match: re.Match) -> str:
    indent = match.group("indent")
    lines = [line.strip() for line in match.group("body").splitlines() if line.strip()]
    return f"{indent}$$\n" + "".join(f"{indent}{line}\n" for line in lines) + f"{indent}$$\n\n"


def convert(text: str, obj: griffe.Object | None = None, resolve: Resolver = _no_links) -> str:
    """``text`` with its reST roles and math blocks in the site's Markdown.

    ``resolve`` maps a role's target (as written, relative to ``obj``) to the public path it is
    documented under, or None; the default links nothing.
    """
    text = _MATH_BLOCK.sub(_math_block, text if text.endswith("\n") else text + "\n")
    text = _MATH.sub(lambda m: f"${m.group(1)}$", text)
    text = _ROLE.sub(lambda m: _reference(bool(m.group(2)), m.group(3), obj, resolve), text)
    text = _DEFAULT_ROLE.sub(lambda m: _reference(True, m.group(1), obj, resolve), text)
    return text.rstrip("\n")


def _api_pages():
    """The ``api_pages`` hook (beside this file), which decides what the reference documents."""
    spec = importlib.util.spec_from_file_location(
        "bayes_fdi_docs_api_pages", Path(__file__).with_name("api_pages.py")
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _target(obj: griffe.Object | griffe.Alias) -> griffe.Object | None:
    try:
        return obj.final_target if obj.is_alias else obj
    except (griffe.AliasResolutionError, griffe.CyclicAliasError):
        return None


def documented_paths(loader: griffe.GriffeLoader) -> dict[str, str]:
    """``{path: public path}`` of what the API reference documents, canonical paths included.

    A documented name's public path and the path of the object it stands for both map to the
    public path; so do their public members (inherited ones included) for a class.
    """
    api_pages = _api_pages()
    faces = api_pages.public_faces()
    out: dict[str, str] = {}
    for package, face in faces.items():
        own, _ = api_pages.page_names(package, faces)
        out.setdefault(package, package)
        for name in own:
            public = api_pages.render_path(package, name, face)
            try:
                target = _target(loader.modules_collection.get_member(public))
            except KeyError:
                continue
            if target is None:
                continue
            out.setdefault(public, public)
            out.setdefault(target.path, public)
            if target.is_class:
                for member_name, member in target.all_members.items():
                    if member_name.startswith("_"):
                        continue
                    out.setdefault(f"{public}.{member_name}", f"{public}.{member_name}")
                    member_target = _target(member)
                    if member_target is not None:
                        out.setdefault(member_target.path, f"{public}.{member_name}")
    return out


def _resolver(loader: griffe.GriffeLoader, documented: dict[str, str]) -> Resolver:
    def resolve(target: str, obj: griffe.Object | None) -> str | None:
        candidates = [target]
        if obj is not None:
            first, _, rest = target.partition(".")
            for scope in (obj, obj.parent, obj.module):
                try:
                    full = scope.resolve(first) if scope is not None else None
                except (griffe.NameResolutionError, AttributeError):
                    full = None
                if full:
                    candidates.append(f"{full}.{rest}" if rest else full)
        for path in candidates:
            if path in documented:
                return documented[path]
            try:
                found = _target(loader.modules_collection.get_member(path))
            except KeyError:
                continue
            if found is not None and found.path in documented:
                return documented[found.path]
        return None

    return resolve


def _objects(obj: griffe.Object) -> Iterator[griffe.Object]:
    yield obj
    for member in obj.members.values():
        if not member.is_alias:
            yield from _objects(member)


class ReSTRoles(griffe.Extension):
    """Rewrites every docstring of a loaded package with `convert`, linking documented names."""

    def on_package(self, *, pkg: griffe.Module, loader: griffe.GriffeLoader, **kwargs: Any) -> None:
        resolve = _resolver(loader, documented_paths(loader))
        for obj in _objects(pkg):
            if obj.docstring is not None:
                obj.docstring.value = convert(obj.docstring.value, obj, resolve)
