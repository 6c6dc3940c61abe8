"""avblocks.environment."""
