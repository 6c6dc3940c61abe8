"""Deferred import of JAX (an optional extra) with a clear error."""

from __future__ import annotations

import os
import sys

from ..errors import AvError

_started = False


def jax():
    """The ``jax`` module, or an AvError telling how to install it.

    When this is the first import of JAX in the process and neither
    ``JAX_NUM_CPU_DEVICES`` nor XLA's ``--xla_force_host_platform_device_count``
    (in ``XLA_FLAGS``) says how many, JAX is asked for one CPU device per
    core, so compiled runs can use them all (see
    :mod:`avblocks.core.compiled.devices`)."""
    global _started
    fresh = not _started and "jax" not in sys.modules
    try:
        import jax as _jax
    except ImportError as e:  # pragma: no cover - depends on the extra
        raise AvError("backend='jax' needs JAX: pip install 'avblocks[jax]' "
                      "(or run with backend='numpy')") from e
    if not _started:
        _started = True
        if fresh and "JAX_NUM_CPU_DEVICES" not in os.environ and \
                "xla_force_host_platform_device_count" not in os.environ.get("XLA_FLAGS", ""):
            try:
                _jax.config.update("jax_num_cpu_devices", default_cpu_devices())
            except (RuntimeError, AttributeError, KeyError):  # pragma: no cover
                pass                    # started already, or an older JAX
    return _jax


def default_cpu_devices() -> int:
    """CPU devices avblocks asks JAX for when it starts JAX itself: one
    per core this process may use, at most 16."""
    try:
        n = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # pragma: no cover - not on Linux
        n = os.cpu_count() or 1
    return max(1, min(16, n))


def x64(flag):
    """Context manager: trace/run with 64-bit types on or off (scoped, not
    the process-wide switch)."""
    j = jax()
    if hasattr(j, "enable_x64"):
        return j.enable_x64(bool(flag))
    from jax import experimental as je  # older JAX releases
    return je.enable_x64() if flag else je.disable_x64()
