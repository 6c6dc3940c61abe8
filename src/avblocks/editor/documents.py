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


def scenario_data(document) -> dict:
    """The scenario mapping of a document: everything but the editor's key."""
    if not isinstance(document, dict):
        raise EditorError("a document is a mapping (the scenario file's sections)",
                          kind="BadDocument")
    return {k: v for k, v in document.items() if k != EDITOR_KEY}
