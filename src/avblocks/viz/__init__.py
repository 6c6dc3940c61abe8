"""avblocks.viz."""
