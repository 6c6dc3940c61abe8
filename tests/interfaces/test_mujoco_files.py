"""A scenario's MJCF scene reads files only under the scenario's folder.

Each escaping case is first shown to be real: MuJoCo itself, loading the
same MJCF without the check, follows the name out of the folder (the
model compiles with the outside file in it). With the scenario's folder
(``mujoco_scene: {mjcf: ...}``) the same file is refused before MuJoCo
reads it, with a ScenarioError naming the scenario file, the entry, the
MJCF file, the element and the path. The accepted layout (an include and
meshes in subfolders) loads and runs: the mesh's mass is the density
times the tetrahedron's volume, the body falls as z0 - g t^2 / 2.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

import avblocks as av
from avblocks.scenarios import Scenario

from ._mj import need

pytestmark = pytest.mark.mujoco

#: a tetrahedron with legs of 1 m: volume 1/6 m^3
TETRA = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"
#: a texture / height field file (never decoded: every case naming one is refused)
PNG = b"not read"
DRONE = ('<mujoco><worldbody><body name="uav0" pos="0 0 5"><freejoint/>'
         '<geom type="mesh" mesh="tetra"/></body></worldbody></mujoco>')


@pytest.fixture(scope="module")
def mj():
    need("mujoco")
    from avblocks.interfaces import mujoco
    return mujoco


def _write(path, text):
    path.parent.mkdir(parents=True, exist_ok=True)
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text)
    return path


def _scenario(folder, mjcf="scene.xml"):
    return Scenario({"name": "s", "blocks": {
        "world": {"type": "interfaces.mujoco.PhysicsWorld", "period": 0.01,
                  "scene": {"mujoco_scene": {"mjcf": mjcf,
                                             "quadrotors": {"uav": ["uav0"]}}}},
        "thrust": {"type": "blocks.Constant", "value": [[0.0, 0.0, 0.0, 0.0]]}},
        "wires": [["thrust.y", "world.wrench"]],
        "simulation": {"t_final": 0.5, "dt": 0.01}}, str(folder / "s.yaml"))


def _layout(tmp_path):
    """``tmp_path/case`` (the scenario's folder) and ``tmp_path/other``
    (outside it), each with a mesh, a texture and an MJCF part."""
    case, other = tmp_path / "case", tmp_path / "other"
    for d in (case, other):
        _write(d / "meshes" / "tetra.obj", TETRA)
        _write(d / "tex.png", PNG)
        _write(d / "part.xml", DRONE)
    return case, other


def _mesh_scene(mesh_file, compiler=""):
    return (f'<mujoco>{compiler}<asset><mesh name="tetra" file="{mesh_file}"/></asset>'
            f'{DRONE[8:]}')


def _refused(folder, *words):
    with pytest.raises(av.ScenarioError) as e:
        _scenario(folder).build(folder / "out")
    msg = str(e.value)
    assert "s.yaml" in msg and "blocks.world.scene.mujoco_scene.mjcf" in msg, msg
    for w in words:
        assert w in msg, msg
    assert "outside the folder" in msg, msg
    return msg


def _escapes(mj, case, path_in_other):
    """MuJoCo, unchecked, reads the file: the case is a real escape."""
    scene = mj.Scene.from_mjcf(str(case / "scene.xml"), quadrotors={"uav": ["uav0"]})
    assert scene.model.nbody >= 2
    assert path_in_other.is_file()


def test_an_include_that_escapes_is_refused(mj, tmp_path):
    case, other = _layout(tmp_path)
    _write(other / "part.xml", '<mujoco><asset><mesh name="tetra" '
           f'file="{case / "meshes" / "tetra.obj"}"/></asset>{DRONE[8:]}')
    _write(case / "scene.xml", '<mujoco><include file="../other/part.xml"/></mujoco>')
    _escapes(mj, case, other / "part.xml")
    _refused(case, "scene.xml", '<include file="../other/part.xml">')


def _nested_escape(tmp_path):
    """``sub/a.xml`` of the case includes ``../../other/assets.xml``, outside it."""
    case, other = _layout(tmp_path)
    _write(other / "assets.xml", '<mujoco><asset><mesh name="tetra" '
           f'file="{case / "meshes" / "tetra.obj"}"/></asset></mujoco>')
    _write(case / "sub" / "a.xml", '<mujoco><include file="../../other/assets.xml"/>'
           '</mujoco>')
    return case, other


def test_a_nested_include_that_escapes_is_refused(mj, tmp_path):
    case, other = _nested_escape(tmp_path)
    _write(case / "scene.xml", f'<mujoco><include file="sub/a.xml"/>{DRONE[8:]}')
    _escapes(mj, case, other / "assets.xml")
    _refused(case, "'sub/a.xml'", '<include file="../../other/assets.xml">')


@pytest.mark.parametrize("tag", ['<include xmlns="urn:x" file="sub/a.xml"/>',
                                 '<include xmlns:m="urn:x" file="sub/a.xml"/>'])
def test_an_include_in_a_namespace_cannot_hide_a_nested_one(mj, tmp_path, tag):
    """The standard library's XML reader names ``<include xmlns="urn:x">``
    ``{urn:x}include``, so the check never looked into the file it
    includes; MuJoCo's reader knows no namespaces and includes it, and its
    nested include escaped (attack42). MJCF uses no namespaces: any is
    refused."""
    case, other = _nested_escape(tmp_path)
    _write(case / "scene.xml", f'<mujoco>{tag}{DRONE[8:]}')
    if 'xmlns="' in tag:
        _escapes(mj, case, other / "assets.xml")
    with pytest.raises(av.ScenarioError) as e:
        _scenario(case).build(case / "out")
    msg = str(e.value)
    assert "s.yaml" in msg and "namespace" in msg and "scene.xml" in msg, msg


def test_an_asset_dir_that_escapes_is_refused(mj, tmp_path):
    case, other = _layout(tmp_path)
    _write(case / "scene.xml", _mesh_scene("tetra.obj", '<compiler meshdir="../other/meshes"/>'))
    _escapes(mj, case, other / "meshes" / "tetra.obj")
    _refused(case, '<compiler meshdir="../other/meshes">', "names a folder")


@pytest.mark.parametrize("attr", ["assetdir", "texturedir"])
def test_the_other_dirs_that_escape_are_refused(mj, tmp_path, attr):
    case, other = _layout(tmp_path)
    _write(case / "scene.xml", _mesh_scene("meshes/tetra.obj", f'<compiler {attr}="{other}"/>'))
    _refused(case, f'<compiler {attr}="{other}">')


def test_an_absolute_asset_path_is_refused(mj, tmp_path):
    case, other = _layout(tmp_path)
    target = other / "meshes" / "tetra.obj"
    _write(case / "scene.xml", _mesh_scene(str(target)))
    _escapes(mj, case, target)
    _refused(case, f'<mesh file="{target}">')


def test_an_absolute_asset_path_inside_the_folder_is_accepted(mj, tmp_path):
    case, _other = _layout(tmp_path)
    _write(case / "scene.xml", _mesh_scene(str(case / "meshes" / "tetra.obj")))
    d, _sim = _scenario(case).build(case / "out")
    assert d["world"].block.scene.model.nmesh == 1


@pytest.mark.skipif(not hasattr(os, "symlink"), reason="no symbolic links")
def test_a_symlink_that_points_out_is_refused(mj, tmp_path):
    case, other = _layout(tmp_path)
    (case / "meshes" / "link.obj").symlink_to(other / "meshes" / "tetra.obj")
    _write(case / "scene.xml", _mesh_scene("meshes/link.obj"))
    _escapes(mj, case, other / "meshes" / "tetra.obj")
    _refused(case, '<mesh file="meshes/link.obj">')


def test_a_symlinked_folder_that_points_out_is_refused(mj, tmp_path):
    case, other = _layout(tmp_path)
    (case / "theirs").symlink_to(other, target_is_directory=True)
    _write(case / "scene.xml", '<mujoco><include file="theirs/part.xml"/>'
           '<asset><mesh name="tetra" file="meshes/tetra.obj"/></asset></mujoco>')
    _escapes(mj, case, other / "part.xml")
    _refused(case, '<include file="theirs/part.xml">')


# every attribute of the MuJoCo XML reference that names a file, one by one
@pytest.mark.parametrize("element", [
    '<asset><texture name="t" type="2d" file="{o}/tex.png"/></asset>',
    '<asset><texture name="t" type="cube" fileright="{o}/tex.png" fileleft="tex.png" '
    'fileup="tex.png" filedown="tex.png" filefront="tex.png" fileback="tex.png"/></asset>',
    '<asset><texture name="t" type="cube" fileright="tex.png" fileleft="tex.png" '
    'fileup="tex.png" filedown="tex.png" filefront="tex.png" fileback="../other/tex.png"/>'
    '</asset>',
    '<asset><hfield name="h" size="1 1 1 1" file="../other/tex.png"/></asset>',
    '<asset><skin file="../other/body.skn"/></asset>',
    '<deformable><skin file="{o}/body.skn"/></deformable>',
    '<asset><model name="m" file="../other/part.xml"/></asset>',
    '<worldbody><flexcomp name="f" type="mesh" file="../other/meshes/tetra.obj" '
    'dim="2"/></worldbody>',
])
def test_every_file_attribute_is_checked(mj, tmp_path, element):
    case, other = _layout(tmp_path)
    element = element.replace("{o}", str(other))
    _write(case / "scene.xml", f'<mujoco>{element}'
           '<asset><mesh name="tetra" file="meshes/tetra.obj"/></asset>'
           f'{DRONE[8:]}')
    inner = element[element.index("<", 1) + 1:].split()[0]      # the element's tag
    bad = next(w for w in element.split() if "other" in w).split("/>")[0]
    _refused(case, "scene.xml", f"<{inner} {bad}>")


def test_a_sub_models_own_files_are_checked_from_its_folder(mj, tmp_path):
    case, other = _layout(tmp_path)
    _write(case / "models" / "m.xml", '<mujoco><asset><mesh name="x" '
           'file="../../other/meshes/tetra.obj"/></asset><worldbody><body name="q">'
           '<geom type="mesh" mesh="x"/></body></worldbody></mujoco>')
    _write(case / "scene.xml", '<mujoco><asset><model name="m" file="models/m.xml"/>'
           f'<mesh name="tetra" file="meshes/tetra.obj"/></asset>{DRONE[8:]}')
    _refused(case, "'models/m.xml'", '<mesh file="../../other/meshes/tetra.obj">')


def test_a_doctype_or_a_non_mjcf_root_is_refused(mj, tmp_path):
    case, _other = _layout(tmp_path)
    sc = _scenario(case)
    _write(case / "scene.xml", '<!DOCTYPE m [<!ENTITY x "../other">]><mujoco/>')
    with pytest.raises(av.ScenarioError, match="DOCTYPE"):
        sc.build(case / "out")
    _write(case / "scene.xml", '<robot name="r"><link name="a"/></robot>')
    with pytest.raises(av.ScenarioError, match="not MJCF"):
        sc.build(case / "out")


def test_an_include_and_meshes_in_subfolders_load_and_run(mj, tmp_path):
    case, _other = _layout(tmp_path)
    _write(case / "parts" / "drone.xml", f"<mujoco>{DRONE[8:]}")
    _write(case / "parts" / "assets.xml", '<mujoco><asset><mesh name="tetra" '
           'file="tetra.obj"/></asset></mujoco>')
    _write(case / "scene.xml", '<mujoco><compiler meshdir="meshes"/>'
           '<include file="parts/assets.xml"/><include file="parts/drone.xml"/></mujoco>')
    d, sim = _scenario(case).build(case / "out")
    m = d["world"].block.scene.model
    assert m.nmesh == 1 and m.mesh_vertnum[0] == 4
    # MuJoCo's default density 1000 kg/m^3 times the tetrahedron's 1/6 m^3
    assert m.body_mass[1] == pytest.approx(1000.0 / 6.0, rel=1e-9)
    r = av.simulate(d, progress=False, **sim)
    t = np.asarray(r.t)
    z = np.asarray(r["world.position"])[:, 0, 2]
    z0 = z[0]
    np.testing.assert_allclose(z, z0 - 0.5 * 9.81 * t**2, atol=0.01)
    assert t[-1] == pytest.approx(0.5)
