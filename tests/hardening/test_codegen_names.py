"""No name reaches the generated NumPy step as code (issue 42).

``core/codegen.py`` writes a diagram's major step as Python source and
compiles it. The only texts it takes from a diagram are port and state
names, written as string literals (``repr``); block and parameter names
never enter the source (blocks are referred to by index). Port and state
names must be identifiers (``Port`` refuses anything else), so a name such
as ``x'] ; import os`` is refused when it is declared, and names that are
identifiers but dangerous as code (keywords, ``__import__``, names Python
folds together such as "\\ufb01" and "fi") stay literals.

Python's parser judges the source: every name it holds is one the writer
makes itself, every user name is a string constant; the results equal the
generic engine's bit for bit.
"""

from __future__ import annotations

import ast

import numpy as np
import pytest

import avblocks as av
from avblocks.core.errors import AvError

NAMES = ["class", "None", "__import__", "__builtins__", "\ufb01", "fi", "\u00e9",
         "x" * 300, "match", "_", "print", "np", "X", "Y", "t", "h", "k1_0", "out0"]
class Named(av.Block):
    """A continuous state and a discrete state named by the test, an input
    and an output named by the test: dx/dt = u, z counts hits."""

    def __init__(self, name, n=2):
        super().__init__()
        self.declare_periodic(0.1)
        self.declare_input(name, (n, 2))
        self.declare_output(name, (n, 2))
        self.declare_continuous_state(name, np.zeros((n, 2)))
        self.declare_discrete_state("d_" + name[:20], np.zeros(1))

    def output(self, t, x, u, xp):
        return {list(self._outputs)[0]: x[self.state_name]}

    @property
    def state_name(self):
        return list(self._cstates)[0]

    def derivative(self, t, x, u, xp):
        return {self.state_name: u[list(self._inputs)[0]]}

    def update(self, t, x, u, xp):
        return {list(self._dstates)[0]: x[list(self._dstates)[0]] + 1.0}


def _diagram(name):
    d = av.Diagram("hostile")
    c = d.add(av.blocks.Constant(np.ones((2, 2))), name=name if name.isidentifier()
              else "c")
    b = d.add(Named(name), name="b_" + name[:50] if ("b_" + name[:50]).isidentifier()
              else "b")
    d.connect(c.y, b.port(name))
    return d


def _code_names(tree):
    return sorted((type(n).__name__, getattr(n, "id", None) or getattr(n, "attr", None)
                   or getattr(n, "arg", None))
                  for n in ast.walk(tree)
                  if isinstance(n, (ast.Name, ast.Attribute, ast.arg, ast.keyword)))


def _run(d, solver, steps=10):
    sim = av.Simulator(d, 0.1, solver).init()
    for _ in range(steps):
        sim.step()
    return sim, [{k: np.array(v) for k, v in x.items()} for x in sim.X]


@pytest.mark.parametrize("name", NAMES, ids=[n[:12] for n in NAMES])
@pytest.mark.parametrize("solver", ["euler", "rk4"])
def test_names_are_literals_of_the_generated_step(name, solver, monkeypatch):
    sim, fast = _run(_diagram(name), solver)
    src = sim._fast.source
    tree = ast.parse(src)
    # the same code as for a plain name: the same Python names, attributes
    # and calls; only string constants differ
    base = ast.parse(_run(_diagram("u"), solver)[0]._fast.source)
    assert _code_names(tree) == _code_names(base)
    consts = {n.value for n in ast.walk(tree) if isinstance(n, ast.Constant)}
    assert name in consts                          # the name is a string constant
    assert "hostile" not in src
    monkeypatch.setattr(av.Simulator, "use_codegen", False)
    plain, generic = _run(_diagram(name), solver)
    assert plain._fast is None
    for a, b in zip(fast, generic, strict=True):
        assert a.keys() == b.keys()
        for k in a:
            assert a[k].tobytes() == b[k].tobytes(), k
    # dx/dt = 1 from x = 0 for ten steps of 0.1 s: x = 1 (exact for a constant rate)
    x = fast[1][name]
    np.testing.assert_allclose(x, 1.0, rtol=1e-12)
    assert fast[1]["d_" + name[:20]][0] == 10.0      # one hit per step


@pytest.mark.parametrize("bad", ["x'] ; import os #", "a b", "a.b", "1x", "", "x\n",
                                 "x']}\n__import__('os')\n#"])
def test_names_that_are_no_identifiers_are_refused_when_declared(bad):
    with pytest.raises(AvError, match="identifier"):
        Named(bad)
    with pytest.raises(AvError, match="identifier"):
        av.viz.Scope(inputs=[bad])
