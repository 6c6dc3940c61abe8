"""The editor's error: a request it refuses, with the HTTP status it maps to.

Every operation raises :class:`EditorError` (or a library error) for bad
input; :func:`error_json` turns any exception into the ``{"error": {...}}``
body of ``API.md``.
"""

from __future__ import annotations

from ..core.errors import AvError


class EditorError(AvError):
    """A request the editor refuses; ``status`` is the HTTP status it maps to
    (400 bad request, 404 unknown file or run, 409 file changed on disk,
    413 too large)."""

    def __init__(self, cause, *, status=400, kind=None, errors=None, hint=None):
        self.status = int(status)
        self.kind = kind or "EditorError"
        self.errors = errors
        super().__init__(cause, hint=hint)

    def to_json(self) -> dict:
        out = {"message": str(self), "kind": self.kind}
        if self.errors is not None:
            out["errors"] = self.errors
        return out


def error_json(e: BaseException) -> tuple[int, dict]:
    """``(HTTP status, {"error": {...}})`` for an exception an operation raised."""
    if isinstance(e, EditorError):
        return e.status, {"error": e.to_json()}
    if isinstance(e, AvError):
        return 400, {"error": {"message": str(e), "kind": type(e).__name__}}
    return 500, {"error": {"message": f"{type(e).__name__}: {e}", "kind": "InternalError"}}
