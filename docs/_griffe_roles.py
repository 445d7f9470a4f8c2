"""A griffe extension for the API reference: Sphinx cross-reference roles in docstrings as code.

The docstrings are numpydoc and cite other objects with Sphinx roles (``:func:`build_abstraction```,
``:class:`~tubejax.transitions.transition_system.TransitionSystem```). mkdocstrings does not read these roles, so this
extension (loaded by ``mkdocs.yml``) shows each one as inline code, the ``~`` form by its last
component, as Sphinx would. It changes only the rendered text, never the code.
"""

from __future__ import annotations

import re

import griffe

_ROLE = re.compile(r":(?:py:)?(?:func|class|meth|mod|data|attr|exc|obj|const|ref|term):`(~?)([^`<]+?)(?:\s*<[^`>]*>)?`")


def _code(m: re.Match) -> str:
    tilde, target = m.groups()
    name = target.strip().lstrip(".")
    if tilde:
        name = name.rsplit(".", 1)[-1]
    return f"`{name}`"


class SphinxRolesAsCode(griffe.Extension):
    """Rewrite ``:role:`target``` to ```target``` in every docstring."""

    def on_instance(self, *, obj: griffe.Object, **kwargs) -> None:
        doc = obj.docstring
        if doc is not None and ":" in doc.value:
            doc.value = _ROLE.sub(_code, doc.value)
