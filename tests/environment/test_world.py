"""World: obstacle kinds, loaders (GeoJSON, WKT, occupancy, image), bounds."""

import json

import numpy as np
import pytest
import shapely

import avblocks as av
from avblocks.environment import Background, Circle, Disc, World, collide, rectangle


def test_kinds_and_segments():
    w = World([[(0, 0), (2, 0), (1, 1)], rectangle(5, 5, 6, 7), Circle((10, 0), 2.0)])
    assert w.n_obstacles == 3
    assert w.is_circle.tolist() == [False, False, True]
    assert len(w.segments) == 3 + 4 and w.segment_owner.tolist() == [0] * 3 + [1] * 4
    np.testing.assert_allclose(w.circle_radius, [0, 0, 2.0])
    assert w.is_free([[1, 0.5], [5.5, 6], [10, 1.5], [3, 3]]).tolist() == [False, False,
                                                                         False, True]
    assert w.is_free([[3, 3]], clearance=2.8).tolist() == [True]
    assert w.is_free([[3, 3]], clearance=2.9).tolist() == [False]


def test_multipolygon_and_holes_split_and_kept():
    mp = shapely.MultiPolygon([shapely.box(0, 0, 1, 1), shapely.box(3, 3, 4, 4)])
    donut = shapely.box(-5, -5, 5, 5).difference(shapely.box(-1, -1, 1, 1))
    w = World([mp, donut])
    assert w.n_obstacles == 3
    assert len(w.segments) == 4 + 4 + 8  # the hole's edges too


def test_geojson_and_wkt():
    fc = {"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {},
         "geometry": {"type": "Polygon", "coordinates": [[[0, 0], [4, 0], [4, 1], [0, 1],
                                                          [0, 0]]]}},
        {"type": "Feature", "properties": {"radius": 0.5},
         "geometry": {"type": "Point", "coordinates": [10, 10]}},
    ]}
    w1 = World.from_geojson(fc)
    w2 = World.from_geojson(json.dumps(fc))
    for w in (w1, w2):
        assert w.n_obstacles == 2 and w.is_circle.tolist() == [False, True]
        assert w.geoms[0].area == pytest.approx(4.0)
    w3 = World.from_wkt(["POLYGON ((0 0, 4 0, 4 1, 0 1, 0 0))",
                         "MULTIPOLYGON (((5 5, 6 5, 6 6, 5 5)), ((8 8, 9 8, 9 9, 8 8)))"],
                        bounds=(0, 0, 10, 10))
    assert w3.n_obstacles == 3 and w3.bounds == (0, 0, 10, 10)
    with pytest.raises(av.ParameterError):
        World.from_geojson({"type": "Point", "coordinates": [0, 0]})


def test_geojson_file(tmp_path):
    p = tmp_path / "w.geojson"
    p.write_text(json.dumps({"type": "Polygon",
                             "coordinates": [[[0, 0], [1, 0], [1, 1], [0, 0]]]}))
    assert World.from_geojson(str(p)).n_obstacles == 1


GRID = np.array([[1, 1, 0, 0],
                 [1, 1, 0, 1],
                 [0, 0, 0, 1]])  # row 0 is the top of the map


def test_occupancy_cells_merged():
    w = World.from_occupancy(GRID, 0.5, origin=(10.0, 20.0))
    assert w.n_obstacles == 2  # the 2x2 block and the 2x1 bar
    assert w.bounds == (10.0, 20.0, 12.0, 21.5)
    areas = sorted(g.area for g in w.geoms)
    assert areas == pytest.approx([0.5, 1.0])
    assert sorted(len(g.exterior.coords) for g in w.geoms) == [5, 5]  # merged squares
    # top-left block spans x in [10, 11], y in [20.5, 21.5]
    assert w.is_free([[10.5, 21.0], [10.5, 20.25], [11.75, 20.5], [11.25, 21.25]]).tolist() == [
        False, True, False, True]
    up = World.from_occupancy(GRID, 0.5, origin=(10.0, 20.0), image_rows=False)
    assert up.is_free([[10.5, 20.5]]).tolist() == [False]


def test_occupancy_with_hole_and_collision():
    g = np.ones((5, 5), bool)
    g[1:4, 1:4] = False
    w = World.from_occupancy(g, 1.0)
    assert w.n_obstacles == 1 and len(w.geoms[0].interiors) == 1
    r = collide(w, np.array([[2.5, 2.5], [1.4, 2.5]]), Disc(0.4))
    assert r["hit_obstacle"].tolist() == [False, True]


def test_image_file_and_background(tmp_path):
    from PIL import Image
    img = np.where(GRID == 1, 0, 255).astype(np.uint8)  # dark = occupied
    p = tmp_path / "map.png"
    Image.fromarray(img).save(p)
    w = World.from_image(p, 0.5, origin=(10.0, 20.0))
    ref = World.from_occupancy(GRID, 0.5, origin=(10.0, 20.0))
    assert shapely.equals(shapely.union_all(w.geoms), shapely.union_all(ref.geoms))
    assert isinstance(w.background, Background)
    assert w.background.extent == (10.0, 12.0, 20.0, 21.5)
    assert w.background.image.shape == (3, 4, 3)


def test_errors_and_sampling():
    with pytest.raises(av.ParameterError):
        World([[(0, 0), (1, 1)]])
    with pytest.raises(av.ParameterError):
        World([], walls=True)
    with pytest.raises(av.ParameterError):
        Circle((0, 0), -1)
    w = World([rectangle(0, 0, 5, 10)], bounds=(0, 0, 10, 10))
    pts = w.sample_free(50, seed=2, clearance=0.5)
    assert pts.shape == (50, 2) and np.all(pts[:, 0] >= 5.5)
    bg = Background(np.zeros((4, 6)), (0, 10, 0, 5))
    assert World(background=bg).background.extent == (0.0, 10.0, 0.0, 5.0)
