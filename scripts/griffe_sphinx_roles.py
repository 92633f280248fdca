"""Griffe extension for ``make docs``: render the docstrings' Sphinx markup in Markdown.

The numpydoc docstrings use Sphinx roles (``:func:`segment```, ``:class:`~a.b.C```,
``:DOI:`...```) and citation labels (``.. [1] ...``), which Markdown would show verbatim.
This rewrites them, before mkdocstrings parses the docstrings, into inline code, DOI links
and a plain list; the source files keep their numpydoc/Sphinx form.
"""

from __future__ import annotations

import re
from typing import Any

import griffe

_ROLE = re.compile(r":(?:py:)?(?:func|class|meth|mod|attr|data|exc|obj|const):`([^`]+)`")
_DOI = re.compile(r":DOI:`([^`]+)`", re.IGNORECASE)
_CITATION = re.compile(r"^(\s*)\.\. \[([^\]]+)\]", re.MULTILINE)


def _role_target(match: re.Match[str]) -> str:
    target = match.group(1).strip()
    if target.startswith("~"):  # Sphinx: show only the last component
        target = target[1:].rsplit(".", 1)[-1]
    return f"`{target.lstrip('.')}`"


def rewrite(text: str) -> str:
    """Return ``text`` with Sphinx roles and citation labels turned into Markdown."""
    text = _ROLE.sub(_role_target, text)
    text = _DOI.sub(lambda m: f"[doi:{m.group(1)}](https://doi.org/{m.group(1)})", text)
    return _CITATION.sub(lambda m: f"{m.group(1)}- [{m.group(2)}]", text)


class SphinxRoles(griffe.Extension):
    """Rewrite each object's docstring as it is loaded."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = rewrite(obj.docstring.value)
