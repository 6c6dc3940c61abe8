"""The application layer's commands: one module per ``avblocks`` sub-command.

Each module has ``add_parser(sub)`` (its argparse sub-command) and the
``cmd_*`` function it runs; :mod:`avblocks.cli` assembles them. What the
commands share sits below them: loading a target and ``--set`` overrides
(:mod:`avblocks.scenarios.targets`), and the run guard -- signals, output
folder, atomic files, memory check -- (:mod:`avblocks._runio`).
``avblocks sweep`` is :mod:`avblocks.commands.sweep` (its body lives with the
sweep, :mod:`avblocks.sweep.cli`).
"""
