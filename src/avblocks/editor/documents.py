"""What a document is: a scenario file's sections plus the editor's own key."""

from __future__ import annotations

from .errors import EditorError

#: The document's own key (layout, groups, viewport): not part of the scenario.
EDITOR_KEY = "editor"
#: What a new, empty document holds.
EMPTY_DOCUMENT = {
    "name": "untitled",
    "parameters": {"agents": 15, "seed": 1},
    "blocks": {},
    "wires": [],
    "simulation": {"t_final": 30, "dt": 0.02},
}


#: Sections of a document that are text when given.
TEXT_SECTIONS = ("name", "description")


def scenario_data(document) -> dict:
    """The scenario mapping of a document: everything but the editor's key.

    A document that is not a mapping, or whose ``name`` or ``description``
    is not text, is refused (400 ``BadDocument``)."""
    if not isinstance(document, dict):
        raise EditorError("a document is a mapping (the scenario file's sections)",
                          kind="BadDocument")
    for key in TEXT_SECTIONS:
        v = document.get(key)
        if v is not None and not isinstance(v, str):
            raise EditorError(f"the diagram's {key} is text, not {type(v).__name__}",
                              kind="BadDocument", hint=f"found {str(v)[:80]}")
    return {k: v for k, v in document.items() if k != EDITOR_KEY}
