"""avblocks.scenarios."""
