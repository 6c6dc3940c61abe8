"""The compiled engine's XLA options are a preference, not a requirement: a
jaxlib whose CPU compiler no longer knows one (JAX 0.11 dropped
``xla_cpu_use_fusion_emitters``) compiles with its defaults instead."""

import numpy as np
import pytest

jax = pytest.importorskip("jax")

from avblocks.core.compiled import program  # noqa: E402


def test_unknown_option_falls_back_to_defaults(monkeypatch):
    monkeypatch.setattr(program, "compiler_options",
                        lambda: {"xla_avblocks_no_such_option": True})
    monkeypatch.setitem(program._OPTIONS_OK, "cpu", True)
    lowered = jax.jit(lambda x: 2.0 * x + 1.0).lower(np.arange(3.0))
    with pytest.raises(Exception, match="No such compile option"):
        lowered.compile({"xla_avblocks_no_such_option": True})
    exe = program.compile_lowered(lowered)
    np.testing.assert_allclose(np.asarray(exe(np.arange(3.0))), [1.0, 3.0, 5.0])
    assert program._OPTIONS_OK["cpu"] is False


def test_other_compile_errors_are_not_swallowed(monkeypatch):
    class Lowered:
        def compile(self, opts=None):
            raise RuntimeError("out of memory")
    monkeypatch.setattr(program, "compiler_options", lambda: {"x": 1})
    with pytest.raises(RuntimeError, match="out of memory"):
        program.compile_lowered(Lowered())
