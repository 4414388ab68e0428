"""Floor-plan loaders: GeoJSON, WKT, mesh slice; bad input names the file."""

import json

import numpy as np
import pytest
import shapely

from explore.floorplan import FloorPlan, FloorPlanError, floor_plan_from_mesh, load_floor_plan
from ibr.synthetic import make_world


def test_geojson_and_wkt_round_trip(tmp_path):
    free = make_world("courtyard").free_space
    gj = tmp_path / "site.geojson"
    gj.write_text(json.dumps({"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {}, "geometry": shapely.geometry.mapping(free)}]}))
    wkt = tmp_path / "site.wkt"
    wkt.write_text(free.wkt)
    for path in (gj, wkt):
        plan = load_floor_plan(path)
        assert plan.free_space.symmetric_difference(free).area < 1e-9
        assert len(plan.wall_segments()) == 8  # two rectangular buildings
    assert len(load_floor_plan(wkt, exterior_is_wall=True).wall_segments()) == 12


def test_mesh_slice_recovers_the_footprints():
    world = make_world("courtyard")
    plan = floor_plan_from_mesh(world.mesh, 0.5)
    assert plan.free_space.symmetric_difference(world.free_space).area < 1e-6
    walls = plan.wall_segments()
    assert np.linalg.norm(walls[:, 1] - walls[:, 0], axis=1).sum() == pytest.approx(76.0, abs=1e-6)


@pytest.mark.parametrize("name,text", [("a.wkt", "POINT (1 2)"), ("b.wkt", "nonsense"),
                                       ("c.geojson", "{\"type\": \"Point\", \"coordinates\": [0, 0]}"),
                                       ("d.geojson", "not json"), ("e.dxf", "")])
def test_bad_floor_plans_name_the_file(tmp_path, name, text):
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(FloorPlanError, match=name):
        load_floor_plan(path)
    with pytest.raises(FloorPlanError, match="missing"):
        load_floor_plan(tmp_path / "missing.wkt")


def test_boundary_segments_flag_walls():
    plan = FloorPlan(shapely.box(0, 0, 10, 10).difference(shapely.box(4, 4, 6, 6)))
    segs, wall = plan.boundary_segments()
    assert len(segs) == 8 and wall.tolist() == [False] * 4 + [True] * 4
