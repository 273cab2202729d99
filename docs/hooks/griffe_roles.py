"""Griffe extension: the reStructuredText roles of the docstrings, rendered as the site renders.

The package's docstrings are numpy-style and read well in ``help()``; a few use reST roles
(``:class:`~bayes_fdi.x.Y```, ``:func:`f```, ``:math:`\\alpha```) and ``.. math::`` blocks that
Markdown would show literally. This extension rewrites each docstring once, as griffe loads it:

- ``:class:``, ``:func:``, ``:meth:``, ``:mod:``, ``:data:``, ``:attr:``, ``:exc:``, ``:obj:`` ->
  inline code of the name (``~`` keeps only its last part, as Sphinx shows it);
- ``:math:`x``` -> ``$x$`` and a ``.. math::`` block -> ``$$ ... $$``, which
  ``pymdownx.arithmatex`` and the ``mathml`` hook render as MathML.

Written by hand: the docstrings stay valid reST for ``help()``; no maintained griffe extension
converts reST roles inside numpy-style docstrings.
"""

from __future__ import annotations

import re
from typing import Any

import griffe

_ROLE = re.compile(r":(?:py:)?(class|func|meth|mod|data|attr|exc|obj):`(~?)([^`]+)`")
_MATH = re.compile(r":math:`([^`]+)`")
_MATH_BLOCK = re.compile(r"^(?P<indent>[ \t]*)\.\. math::[ \t]*\n(?P<body>(?:(?P=indent)?[ \t]*\n|(?P=indent)[ \t]+.*\n)+)", re.M)


def _name(match: re.Match) -> str:
    short, target = match.group(2), match.group(3).strip()
    if "<" in target and target.endswith(">"):  # :class:`text <target>`
        return f"`{target.split('<', 1)[0].strip()}`"
    return f"`{target.rsplit('.', 1)[-1] if short else target}`"


def _math_block(match: re.Match) -> str:
    indent = match.group("indent")
    lines = [line.strip() for line in match.group("body").splitlines() if line.strip()]
    return f"{indent}$$\n" + "".join(f"{indent}{line}\n" for line in lines) + f"{indent}$$\n\n"


def convert(text: str) -> str:
    """``text`` with its reST roles and math blocks in the site's Markdown."""
    text = _MATH_BLOCK.sub(_math_block, text if text.endswith("\n") else text + "\n")
    text = _MATH.sub(lambda m: f"${m.group(1)}$", text)
    return _ROLE.sub(_name, text).rstrip("\n")


class ReSTRoles(griffe.Extension):
    """Rewrites every loaded docstring with `convert`."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = convert(obj.docstring.value)
