"""Helpers for block tests: configure a polymorphic block without a diagram."""

from avblocks.core.ports import Port


def configured(block, **shapes):
    """Fix input shapes as a diagram would and call ``configure``."""
    specs = {}
    for name, spec in shapes.items():
        shape, dtype = (spec if isinstance(spec, tuple) and len(spec) == 2
                        and isinstance(spec[1], str) else (spec, "float64"))
        specs[name] = Port(name, shape, dtype)
        block.redeclare_input(name, shape, dtype)
    block.configure(specs)
    return block


import pytest  # noqa: E402


@pytest.fixture(name="configured")
def _configured():
    return configured
