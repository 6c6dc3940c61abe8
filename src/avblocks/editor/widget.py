"""The editor in a Jupyter cell: ``av.edit(diagram_or_file)`` (anywidget).

The widget's front end is the editor's bundle (``static/widget.js``, which
exports ``{render}``); it talks to the kernel with custom messages
``{id, op, args}`` answered ``{id, ok: true, result}`` or ``{id, ok: false,
error}`` (``API.md``), through the same :class:`EditorService` as the HTTP
server. Each edit that validates updates :attr:`EditorWidget.document` (the
scenario mapping, layout included) and :attr:`EditorWidget.diagram` (the
:class:`~avblocks.Diagram` it builds), so the next cell can simulate it.
"""

from __future__ import annotations

import copy
from pathlib import Path

from ..core.errors import AvError
from .service import EditorError, EditorService, error_json, scenario_data

#: The widget's entry of the built bundle.
WIDGET_JS = Path(__file__).parent / "static" / "widget.js"
_PLACEHOLDER = """
export function render({ model, el }) {
  el.textContent = "avblocks editor: the front end is not built "
    + "(src/avblocks/editor/web: npm ci && npm run build)";
}
export default { render };
"""


def _anywidget():
    try:
        import anywidget
        import traitlets
    except ImportError as e:
        raise EditorError(f"the editor widget needs anywidget ({e})", kind="MissingExtra",
                          hint='pip install "avblocks[editor]"') from None
    return anywidget, traitlets


def _widget_class():
    anywidget, traitlets = _anywidget()

    class EditorWidget(anywidget.AnyWidget):
        """The editor as a Jupyter widget (see :func:`edit`).

        Attributes
        ----------
        document : dict
            The scenario mapping (with the editor's ``layout``), synced with
            the page.
        diagram : Diagram or None
            The diagram the document builds (the last valid one).
        errors : list
            The errors of the last validation (API.md's error records).
        """

        _esm = WIDGET_JS if WIDGET_JS.is_file() else _PLACEHOLDER
        _css = (WIDGET_JS.with_name("widget.css") if WIDGET_JS.with_name("widget.css")
                .is_file() else "")
        document = traitlets.Dict().tag(sync=True)
        path = traitlets.Unicode(None, allow_none=True).tag(sync=True)
        height = traitlets.Int(640).tag(sync=True)

        def __init__(self, service, document, path=None, diagram=None, **kw):
            super().__init__(document=document, path=path, **kw)
            self.service = service
            self.diagram = diagram
            self.errors = []
            self.on_msg(self._on_custom)

        def _on_custom(self, widget, content, buffers):
            if not isinstance(content, dict) or "op" not in content:
                return
            rid = content.get("id")
            try:
                result = self.handle(content["op"], content.get("args") or {})
                reply = {"id": rid, "ok": True, "result": result}
            except (AvError, Exception) as e:  # noqa: BLE001 - every failure answered
                _status, body = error_json(e)
                reply = {"id": rid, "ok": False, "error": body["error"]}
            self.send(reply)

        def handle(self, op, args) -> dict:
            """One operation of API.md; a valid ``validate`` (and ``load``,
            ``save``) updates :attr:`document` and :attr:`diagram`."""
            args = dict(args)
            if op == "validate":
                import time
                t0 = time.perf_counter()
                doc = args.get("document")
                errors, signals, built = self.service.check(doc,
                                                            args.get("path", self.path))
                self.errors = errors
                if built is not None:
                    self.diagram = built[0]
                    self.document = copy.deepcopy(doc)
                return {"ok": not errors, "errors": errors, "signals": signals,
                        "elapsed_ms": round(1e3 * (time.perf_counter() - t0), 2)}
            if op == "status" and "run" in args:
                return self.service.status(args["run"])
            if op == "load" and args.get("current"):     # what av.edit() was given
                return {"document": copy.deepcopy(self.document), "path": self.path,
                        "builtin": None, "revision": None}
            result = self.service.call(op, args)
            if op == "load":
                self.path = result["path"]
                self._adopt(result["document"], check=True)
            elif op == "save":
                self.path = result["path"]
                self._adopt(args.get("document"), check=True)
            return result

        def _adopt(self, doc, check=True):
            errors, _signals, built = self.service.check(doc, self.path, fresh=True)
            self.errors = errors
            if built is not None:
                self.diagram = built[0]
            self.document = copy.deepcopy(doc)

        @property
        def simulation(self) -> dict:
            """The ``simulate`` keyword arguments of the document (its
            ``simulation`` section, ``params`` included)."""
            _d, sim, _sc = self.service.build(self.document, path=self.path)
            return sim

    return EditorWidget


def edit(diagram_or_file=None, *, root=None, blocks=(), height=640):
    """The editor in a Jupyter cell.

    Parameters
    ----------
    diagram_or_file : Diagram, str, path, dict or None
        A diagram built in Python (its blocks with the arguments they were
        constructed with: data only, see
        :func:`avblocks.editor.from_diagram.document_of`), a built-in case
        study name, a scenario file (under ``root``), a scenario mapping, or
        None for an empty diagram.
    root : path, optional
        The folder the editor may read and write (default: the working
        directory).
    blocks : sequence of str
        Modules whose blocks join the palette.
    height : int
        Height of the cell's editor in pixels.

    Returns
    -------
    EditorWidget
        Shows itself in the cell; ``.diagram`` and ``.document`` follow the
        edits.
    """
    from ..core.diagram import Diagram
    cls = _widget_class()
    service = EditorService(root, extra_modules=blocks, figure_urls="data")
    path = None
    x = diagram_or_file
    if x is None:
        doc = service.new()["document"]
    elif isinstance(x, dict):
        doc = copy.deepcopy(x)
        scenario_data(doc)
        service.initial = {"current": True}
    elif isinstance(x, Diagram):
        from .from_diagram import document_of
        doc = document_of(x, modules=blocks)
        service.initial = {"current": True}
    else:
        from ..scenarios.loader import builtin_scenarios
        p = Path(str(x))
        if p.is_file():
            full = p.resolve()
            if service.root not in full.parents:
                service.root = full.parent
            loaded = service.load(path=service._rel(full))
            service.initial = {"path": loaded["path"]}
        elif str(x) in builtin_scenarios():
            loaded = service.load(builtin=str(x))
            service.initial = {"builtin": str(x)}
        else:
            raise EditorError(f"no scenario file or built-in case study '{x}'",
                              status=404, kind="NotFound")
        doc, path = loaded["document"], loaded["path"]
    w = cls(service, doc, path=path, height=int(height))
    w._adopt(doc)
    return w
