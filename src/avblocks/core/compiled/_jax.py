"""Deferred import of JAX (an optional extra) with a clear error."""

from __future__ import annotations

from ..errors import AvError


def jax():
    """The ``jax`` module, or an AvError telling how to install it."""
    try:
        import jax as _jax
    except ImportError as e:  # pragma: no cover - depends on the extra
        raise AvError("backend='jax' needs JAX: pip install 'avblocks[jax]' "
                      "(or run with backend='numpy')") from e
    return _jax


def x64(flag):
    """Context manager: trace/run with 64-bit types on or off (scoped, not
    the process-wide switch)."""
    j = jax()
    if hasattr(j, "enable_x64"):
        return j.enable_x64(bool(flag))
    from jax import experimental as je  # older JAX releases
    return je.enable_x64() if flag else je.disable_x64()
