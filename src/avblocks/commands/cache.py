"""``avblocks cache``: where the compiled backend keeps what it reuses, and clearing it.

    avblocks cache info      # the folder, its size, whether it is on
    avblocks cache clear     # delete the compiled programs and stored plans

Compiled runs (``avblocks run ... --backend jax``, ``simulate(...,
backend="jax")``, ``avblocks.compile``) keep JAX's compiled programs and the
grown neighbour-search plans in the user's cache folder by default
(:func:`avblocks.core.compiled.cache_dir`: ``$AVBLOCKS_CACHE_DIR``, else the
platform's user cache folder, e.g. ``~/.cache/avblocks``), so the next
process with the same diagram starts without compiling. ``--no-cache``,
``cache=False`` or ``AVBLOCKS_CACHE=off`` turn that off (see
:mod:`avblocks.core.compiled.persist` and docs/compiled.md).
"""

from __future__ import annotations


def add_parser(sub):
    c = sub.add_parser("cache", help="the compiled backend's cache folder: info, clear")
    c.add_argument("action", choices=("info", "clear"), help="show it, or delete it")
    c.set_defaults(fn=cmd_cache)
    return c


def _size(root):
    return sum(f.stat().st_size for f in root.rglob("*") if f.is_file()) \
        if root.is_dir() else 0


def cmd_cache(args):
    from ..core.compiled.program import cache_dir, cache_disabled
    root = cache_dir()
    if args.action == "clear":
        from ..core.compiled.program import clear_persistent_cache
        freed = clear_persistent_cache(root)
        print(f"cleared       {root} ({freed / 1e6:.1f} MB)")
        return 0
    print(f"cache folder  {root}")
    print(f"size          {_size(root) / 1e6:.1f} MB "
          f"(compiled programs {_size(root / 'jax') / 1e6:.1f} MB, "
          f"plans {_size(root / 'plans') / 1e6:.3f} MB)")
    print(f"status        {'off (AVBLOCKS_CACHE)' if cache_disabled() else 'on'} for "
          "compiled runs (`--backend jax`, `simulate(..., backend='jax')`)")
    return 0
