"""MkDocs hooks of the documentation site (``mkdocs.yml``: ``hooks``).

The docstrings are numpydoc with Sphinx's cross-reference roles
(``:func:`name```, ``:mod:`name```): mkdocstrings renders them as Markdown, where
the role stays as text before the code span. The role is taken off, leaving the
name as code (as text where Markdown left the backticks, in tooltips).
"""

from __future__ import annotations

import re

_ROLE = r":(?:py:)?(?:func|meth|mod|class|data|attr|exc|obj|const|ref|term|doc):"
_BEFORE_CODE = re.compile(_ROLE + r"(?=<code)")
_IN_BACKTICKS = re.compile(_ROLE + r"`([^`<>]*)`")


def on_page_content(html: str, **kwargs) -> str:
    html = _BEFORE_CODE.sub("", html)
    return _IN_BACKTICKS.sub(r"\1", html)  # in an attribute (a tooltip): the name alone
