"""avblocks.interfaces."""
