"""The browser block-diagram editor: ``avblocks edit`` and ``av.edit()``.

* :mod:`avblocks.editor.service`: the operations (palette, files, load,
  validate, save, run, live, export) as plain Python, shared by both
  transports;
* :mod:`avblocks.editor.server`: the HTTP server (Starlette + uvicorn on
  127.0.0.1, a token in the URL path);
* :mod:`avblocks.editor.widget`: the Jupyter widget (anywidget);
* ``web/``: the TypeScript front end; ``static/``: its built bundle.

The JSON protocol between the two sides is documented in ``API.md`` (and on
the docs page "The editor's JSON API").
"""

from __future__ import annotations

from .server import EditorServer
from .service import EditorError, EditorService
from .widget import edit

__all__ = ["edit", "EditorService", "EditorServer", "EditorError"]
