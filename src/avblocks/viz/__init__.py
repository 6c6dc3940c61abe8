"""Visualization: 2D animation, movies, scopes and signal plots, 3D views,
diagram pictures.

Drawing uses Matplotlib (offscreen Agg when no display); MP4 movies need the
``movie`` extra (imageio-ffmpeg), GIFs only Pillow.
"""

import sys as _sys

from ..core import plotting as _plotting
from .animation import Animation, animate, find_pose, plot_frame, save_movie
from .animation_block import Animation2D
from .diagram import diagram_svg, draw_diagram, to_dot  # noqa: F401 (diagram_svg: backend)
from .movie import MovieWriter, read_video, write_movie
from .scene import Group, Scene2D, obstacle_paths
from .scope import Scope, plot_signals, plot_trajectories
from .shapes import DRAWINGS, Drawing, drawing
from .view3d import Animation3D, animate3d, quat_to_matrix

__all__ = [
    "animate", "save_movie", "plot_frame", "Animation", "Animation2D", "Scene2D", "Group",
    "Drawing", "DRAWINGS", "drawing", "obstacle_paths", "MovieWriter", "write_movie",
    "read_video", "find_pose", "Scope", "plot_signals", "plot_trajectories",
    "animate3d", "Animation3D", "quat_to_matrix",
    "to_dot", "draw_diagram",
]

# the plotting backend of Results.plot/animate and Diagram.to_graphviz (pandas-style)
_plotting.register_backend(__name__, _sys.modules[__name__])
