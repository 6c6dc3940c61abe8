"""The ensemble chunk policy (avblocks.core.compiled.chunking): the log
budget everywhere, a cache-sized working set on a CPU, big chunks on other
platforms; the largest step array of a traced run."""

import os

import pytest

from avblocks.core.compiled import chunking as C
from avblocks.core.errors import ParameterError

if os.environ.get("CI"):
    import jax  # noqa: F401 - in CI the jax extra is installed: never skip
else:
    jax = pytest.importorskip("jax")
pytestmark = pytest.mark.jax


class Dev:
    def __init__(self, platform):
        self.platform = platform


def test_cpu_chunks_hold_a_cache_sized_working_set():
    cpu2 = [Dev("cpu"), Dev("cpu")]
    big = 1 << 40                                  # no log limit
    # 20 kB step arrays: CPU_STEP_BYTES // 20000 runs per device
    per_dev = C.CPU_STEP_BYTES // 20000
    assert C.chunk_size(256, 1000, big, cpu2, lambda: 20000) == 2 * per_dev
    # small arrays: no cache limit, every run in one call (up to the run count)
    assert C.chunk_size(256, 1000, big, cpu2, lambda: 8) == 256
    assert C.chunk_size(256, 1000, big, cpu2, lambda: C.CPU_MIN_ARRAY - 8) == 256
    # an array larger than the budget: still one run per device
    assert C.chunk_size(256, 1000, big, cpu2, lambda: 10 * C.CPU_STEP_BYTES) == 2
    # the log budget wins when it is smaller, rounded to whole runs per device
    assert C.chunk_size(256, 1000, 5000, cpu2, lambda: 8) == 4
    assert C.chunk_size(256, 1000, 5000, [Dev("cpu")], lambda: 8) == 5


def test_gpu_chunks_follow_the_log_budget_only():
    def never():
        raise AssertionError("a GPU chunk does not trace for a step size")
    gpu = [Dev("gpu")]
    assert C.chunk_size(256, 1000, 1 << 40, gpu, never) == 256
    assert C.chunk_size(256, 1000, 64_000, gpu, never) == 64
    assert C.chunk_size(3, 1000, 64_000, gpu, never) == 3


@pytest.mark.parametrize("bad", [0, -2, 1.5, "4", True])
def test_chunk_override_is_taken_as_given_or_refused(bad):
    cpu2 = [Dev("cpu"), Dev("cpu")]
    assert C.chunk_size(256, 1000, 1 << 40, cpu2, lambda: 20000, chunk=7) == 7
    assert C.chunk_size(5, 1000, 1 << 40, cpu2, lambda: 20000, chunk=64) == 5
    with pytest.raises(ParameterError) as e:
        C.chunk_size(256, 1000, 1 << 40, cpu2, lambda: 20000, chunk=bad)
    assert e.value.param == "chunk"


def test_largest_step_array_looks_inside_the_loops_only():
    jnp = jax.numpy

    def run(x):                         # a (7, 7) float32 array inside the scan
        def body(c, _):
            m = c[:, None] * c[None, :]
            return c + m.sum(axis=0), c
        return jax.lax.scan(body, x, None, length=100)
    jp = jax.make_jaxpr(run)(jnp.ones(7, jnp.float32))
    # the stacked (100, 7) output at the top level is not a step array
    assert C.largest_step_array(jp) == 7 * 7 * 4
    assert C.largest_step_array(jax.make_jaxpr(lambda x: x * 2)(jnp.ones(9))) == 0


def test_the_step_probe_is_no_compilation_and_sizes_cpu_chunks():
    import numpy as np

    import avblocks as av
    d = av.Diagram()
    c = d.add(av.blocks.Constant(np.ones((3, 2))), name="c")
    i = d.add(av.blocks.Integrator(np.zeros((3, 2))), name="i")
    d.connect(c.y, i.u)
    runner = av.compile(d, 1.0, dt=0.1, log=["i.y"])
    n = runner.compilations
    ens = runner.ensemble(params={"c.value": np.ones((6, 3, 2))}, x0={"i.x": np.zeros((6, 3, 2))})
    assert runner.compilations == n + 1                 # the ensemble's own compile
    # (3, 2) float64 arrays: every run in one call on a CPU
    assert runner.program.step_bytes(None) == 3 * 2 * 8
    ndev = len(runner.devices)
    if runner.devices[0].platform == "cpu":
        assert ens.meta["chunk_size"] == 6 // ndev * ndev
    np.testing.assert_allclose(ens["i.y"][:, -1], 1.0, atol=1e-12)


def test_chunks_are_evened_out_over_the_calls():
    cpu2 = [Dev("cpu"), Dev("cpu")]
    big = 1 << 40
    # at most 28 runs per call: 32 runs as 2 x 16, not 28 + 28 (padded)
    assert C.chunk_size(32, 1000, 28_000, cpu2, lambda: 8) == 16
    assert C.chunk_size(32, 1000, big, cpu2, lambda: C.CPU_STEP_BYTES // 3) == 6
    # the log budget stays a limit: at most 5 runs per call, 12 runs as 3 x 4
    assert C.chunk_size(12, 1000, 5000, [Dev("gpu")], None) == 4
    assert C.chunk_size(13, 1000, 5000, [Dev("gpu")], None) == 5
    # 7 runs on 2 devices: 2 x 4 (one run of padding), not 6 + 6
    assert C.chunk_size(7, 1000, 1 << 40, cpu2, lambda: 8) == 4
