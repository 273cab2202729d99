"""MkDocs hook: LaTeX formulas rendered to MathML at build time (no JavaScript, no network).

``pymdownx.arithmatex`` (generic mode) wraps ``$...$`` and ``$$...$$`` in
``<span class="arithmatex">\\(...\\)</span>`` / ``<div class="arithmatex">\\[...\\]</div>``; this
hook replaces each with the MathML that ``latex2mathml`` (a Python package) computes, which
browsers render natively. A formula that cannot be converted fails the build, naming the page.
Script tags that would load MathJax or require.js from a CDN (nbconvert's notebook template) are
removed, and the build fails if any other CDN math script remains.
"""

from __future__ import annotations

import html
import re

from latex2mathml.converter import convert

_ARITHMATEX = re.compile(r'<(span|div) class="arithmatex">(.*?)</\1>', re.S)
_CDN_SCRIPT = re.compile(
    r'<script[^>]*src="https?://[^"]*(?:mathjax|MathJax|require\.js|requirejs)[^"]*"[^>]*>\s*</script>'
)
_INLINE_MATHJAX_CONFIG = re.compile(r'<script type="text/x-mathjax-config">.*?</script>', re.S)


def _mathml(match: re.Match, page: str) -> str:
    tag, body = match.group(1), html.unescape(match.group(2)).strip()
    display = "block" if tag == "div" else "inline"
    for left, right in (("\\[", "\\]"), ("\\(", "\\)"), ("$$", "$$"), ("$", "$")):
        if body.startswith(left) and body.endswith(right):
            body = body[len(left) : -len(right)]
            break
    try:
        rendered = convert(body.strip(), display=display)
    except Exception as exc:  # latex2mathml raises its own exception types
        raise ValueError(f"{page}: cannot render the formula {body!r} ({exc})") from exc
    if display == "block":
        return f'<div class="arithmatex">{rendered}</div>'
    return f'<span class="arithmatex">{rendered}</span>'


def on_page_content(html_text, page, config, files):
    """Replace arithmatex's LaTeX by MathML."""
    return _ARITHMATEX.sub(lambda m: _mathml(m, page.file.src_path), html_text)


def on_post_page(output, page, config):
    """Drop CDN MathJax / require.js scripts; fail if a CDN math script is left."""
    output = _CDN_SCRIPT.sub("", output)
    output = _INLINE_MATHJAX_CONFIG.sub("", output)
    if re.search(r"https?://[^\"']*mathjax", output, re.I):
        raise ValueError(f"{page.file.src_path}: a MathJax CDN reference is left in the page")
    return output
