"""Writing a :class:`~avblocks.interfaces.mujoco.scene.Scene` as MJCF text.

Ground (checker, a texture file or plain), the light, a World's obstacles
(circles as cylinders, polygons extruded to prisms, concave ones split into
convex triangles), ground robots (a cylinder on slide x, slide y, hinge z),
quadrotors (free bodies with an airframe and an optional camera) and fixed
cameras; collision bits as the scene module's docstring lists them.
"""

from __future__ import annotations

from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from ...vehicles.quadrotor import rotor_angles


def _f(*vals):
    return " ".join(f"{float(v):.9g}" for v in vals)



class MJCFWriter:
    """The MJCF half of :class:`Scene` (a mix-in: the scene holds the data)."""

    def _obstacles_xml(self, assets, bodies):
        w = self.world
        if w is None:
            return
        import shapely
        h = self.obstacle_height
        rgba = _f(*self.obstacle_color)
        for j, geom in enumerate(w.geoms):
            if w.is_circle[j]:
                c, r = w.circle_center[j], w.circle_radius[j]
                bodies.append(f'<geom name="obstacle{j}" type="cylinder" size="{_f(r, h / 2)}" '
                              f'pos="{_f(c[0], c[1], h / 2)}" rgba="{rgba}" '
                              'contype="3" conaffinity="3"/>')
                continue
            g = geom.buffer(0) if not geom.is_valid else geom
            convex = len(g.interiors) == 0 and abs(g.convex_hull.area - g.area) < 1e-9 * max(
                g.area, 1.0)
            if convex:
                pieces = [np.asarray(g.exterior.coords)[:-1]]
            else:
                if hasattr(shapely, "constrained_delaunay_triangles"):   # shapely >= 2.1
                    tris = shapely.constrained_delaunay_triangles(g).geoms
                else:       # Delaunay of the vertices, keep the triangles inside
                    tris = [t for t in shapely.delaunay_triangles(g).geoms
                            if g.contains(t.representative_point())]
                pieces = [np.asarray(t.exterior.coords)[:-1] for t in tris
                          if t.area > 1e-12]
            for k, pts in enumerate(pieces):
                verts = np.concatenate([np.column_stack([pts, np.zeros(len(pts))]),
                                        np.column_stack([pts, np.full(len(pts), h)])])
                mname = f"obstacle{j}_{k}"
                assets.append(f'<mesh name="{mname}" vertex="{_f(*verts.ravel())}"/>')
                bodies.append(f'<geom name="{mname}" type="mesh" mesh="{mname}" '
                              f'rgba="{rgba}" contype="3" conaffinity="3"/>')

    def _ground_robot_xml(self, g):
        p = g.params
        r, h = p["radius"], p["height"]
        rgba = _f(*p["color"])
        out = []
        for i, b in enumerate(g.bodies):
            m = p["mass"][i]
            izz = 0.5 * m * r * r
            ixx = m * (3 * r * r + h * h) / 12
            vis = (f'<geom type="cylinder" size="{_f(r, h / 2)}" rgba="{rgba}" '
                   f'contype="{0 if g.kinematic else 1}" conaffinity="{0 if g.kinematic else 1}"/>')
            if p.get("marker", True):
                vis += (f'<geom type="box" size="{_f(0.25 * r, 0.12 * r, 0.01)}" '
                   f'pos="{_f(0.6 * r, 0, h / 2 + 0.005)}" rgba="0.95 0.95 0.95 1" '
                        'contype="0" conaffinity="0"/>')
            if g.kinematic:
                x, y, th = p["pose0"][i]
                out.append(f'<body name="{b}" mocap="true" pos="{_f(x, y, h / 2)}" '
                           f'euler="{_f(0, 0, th)}">{vis}</body>')
            else:
                out.append(
                    f'<body name="{b}" pos="{_f(0, 0, h / 2)}">'
                    f'<joint name="{b}_x" type="slide" axis="1 0 0"/>'
                    f'<joint name="{b}_y" type="slide" axis="0 1 0"/>'
                    f'<joint name="{b}_yaw" type="hinge" axis="0 0 1"/>'
                    f'<inertial pos="0 0 0" mass="{_f(m)}" diaginertia="{_f(ixx, ixx, izz)}"/>'
                    f'{vis}</body>')
        return out

    def _quad_xml(self, g):
        p = g.params
        rgba = _f(*p["color"])
        ang = rotor_angles(p["frame"])
        out = []
        for i, b in enumerate(g.bodies):
            arm = p["arm_length"][i]
            col = 0 if g.kinematic else 2
            geoms = [f'<geom type="box" size="{_f(0.3 * arm, 0.3 * arm, 0.04 * 1)}" '
                     f'rgba="{rgba}" contype="{col}" conaffinity="{col}"/>']
            for k, a in enumerate(ang):
                ex, ey = arm * np.cos(a), arm * np.sin(a)
                rc = "0.9 0.9 0.9 0.8" if k in (0, 3) else "0.2 0.2 0.2 0.8"
                geoms.append(f'<geom type="capsule" fromto="{_f(0, 0, 0, ex, ey, 0)}" '
                             f'size="{_f(0.06 * arm)}" rgba="{rgba}" contype="0" conaffinity="0"/>')
                geoms.append(f'<geom type="cylinder" size="{_f(0.45 * arm, 0.005)}" '
                             f'pos="{_f(ex, ey, 0.03)}" rgba="{rc}" contype="0" conaffinity="0"/>')
            cam = ""
            if g.camera is not None:
                c = g.camera
                cam = (f'<camera name="{b}_cam" pos="{_f(*c.pos)}" xyaxes="{_f(*c.xyaxes)}" '
                       f'fovy="{_f(c.fovy)}"/>')
            x, y, z = p["position0"][i]
            if g.kinematic:
                out.append(f'<body name="{b}" mocap="true" pos="{_f(x, y, z)}" '
                           f'quat="{_f(*p["attitude0"][i])}">{"".join(geoms)}{cam}</body>')
            else:
                # the body at its start (qpos0), so the exported MJCF starts there too
                out.append(f'<body name="{b}" pos="{_f(x, y, z)}" '
                           f'quat="{_f(*p["attitude0"][i])}"><freejoint name="{b}_free"/>'
                           f'<inertial pos="0 0 0" mass="{_f(p["mass"][i])}" '
                           f'diaginertia="{_f(*p["inertia"][i])}"/>{"".join(geoms)}{cam}</body>')
        return out

    def to_mjcf(self) -> str:
        """The generated MJCF text (the user's, for :meth:`from_mjcf`)."""
        if self._mjcf is not None:
            return self._mjcf
        assets, world = [], []
        x0, y0, x1, y1 = self.ground_size
        w, h = self.max_image
        if self.ground:
            if self.texture == "checker":
                assets.append('<texture name="groundtex" type="2d" builtin="checker" '
                              'rgb1="0.56 0.58 0.56" rgb2="0.44 0.46 0.44" width="256" '
                              'height="256"/>')
                rep = _f((x1 - x0) / 2, (y1 - y0) / 2)
                assets.append(f'<material name="groundmat" texture="groundtex" '
                              f'texrepeat="{rep}" reflectance="{0.2 if self.shadows else 0}"/>')
                mat = 'material="groundmat"'
            elif self.texture is None:
                mat = 'rgba="0.5 0.52 0.5 1"'
            else:
                assets.append(f'<texture name="groundtex" type="2d" '
                              f'file={quoteattr(str(Path(self.texture).resolve()))}/>')
                assets.append('<material name="groundmat" texture="groundtex" '
                              'texrepeat="1 1" texuniform="false" reflectance="0"/>')
                mat = 'material="groundmat"'
            world.append(f'<geom name="ground" type="plane" '
                         f'size="{_f((x1 - x0) / 2, (y1 - y0) / 2, 0.1)}" '
                         f'pos="{_f((x0 + x1) / 2, (y0 + y1) / 2, 0)}" {mat} '
                         'contype="2" conaffinity="2"/>')
        world.append('<light name="sun" directional="true" pos="0 0 20" dir="0.2 0.1 -1" '
                     f'diffuse="0.7 0.7 0.7" castshadow="{str(self.shadows).lower()}"/>')
        self._obstacles_xml(assets, world)
        for g in self.groups.values():
            world += self._ground_robot_xml(g) if g.kind == "ground" else self._quad_xml(g)
        for name, c in self.fixed_cameras.items():
            world.append(f'<camera name="{name}" pos="{_f(*c["pos"])}" '
                         f'xyaxes="{_f(*c["xyaxes"])}" fovy="{_f(c["fovy"])}"/>')
        return (
            '<mujoco model="avblocks">'
            '<compiler angle="radian"/>'
            f'<option timestep="{_f(self.timestep)}" gravity="{_f(0, 0, -self.gravity)}"/>'
            f'<visual><global offwidth="{w}" offheight="{h}"/>'
            '<headlight ambient="0.35 0.35 0.35" diffuse="0.45 0.45 0.45" specular="0 0 0"/>'
            f'<quality shadowsize="{2048 if self.shadows else 0}"/></visual>'
            f'<asset>{"".join(assets)}</asset>'
            f'<worldbody>{"".join(world)}</worldbody></mujoco>')
