"""Interfaces to the world outside the diagram: 3D physics (``mujoco``),
vision (``vision``), robots. Each is an optional extra, imported only when
used (``import avblocks.interfaces.mujoco``)."""
