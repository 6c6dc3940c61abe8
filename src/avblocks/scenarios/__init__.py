"""Ready-made case studies as scenario files, and the scenario loader.

One way through, each step once and in one place:

* **target -> scenario**: :func:`avblocks.scenarios.targets.open_scenario`
  decides what a name or file is: a YAML/TOML file or a built-in with one
  (:func:`load_scenario`: read safely by ``files.py``, checked by
  :meth:`Scenario.validate`) gives a :class:`Scenario`; a ``.py`` file or a
  Python-only built-in gives a ``PythonScenario`` (its ``make_diagram``).
* **overrides**: ``.with_overrides(--set values)``: the keys are split once
  (scenario parameters, ``simulation.<key>``, ``block.param``).
* **scenario -> diagram**: ``.build(output_dir)`` gives the ``Diagram`` and
  the ``simulate`` arguments; ``block.param`` values are checked against
  the built diagram once. ``.hooks(diagram, sim)`` gives the outcome and
  figures (``report.py``), ``.movie()`` the movie options.
  ``targets.load_any`` (``avblocks run``/``diagram``) and the sweep's cases
  are these steps.
* **scenario -> YAML**: :func:`avblocks.scenarios.document.dump_yaml`
  (``save_document`` for the editor: atomic, confined, keeping the file's
  comments and forms where nothing changed).
"""

from .loader import GENERATORS, Scenario, block_registry, builtin_scenarios, load_scenario

__all__ = ["Scenario", "load_scenario", "builtin_scenarios", "block_registry",
           "GENERATORS"]
