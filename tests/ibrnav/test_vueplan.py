"""`ibrnav vueplan` end to end on a coarse courtyard (small flags)."""

import json

import pytest

from ibr.errors import InputError


def test_vueplan_cli_writes_json_and_table(ibrnav_command, tmp_path, capsys, gl_ctx):
    out = tmp_path / "vp.json"
    assert ibrnav_command(*["vueplan", "synthetic:courtyard", "--candidates", "200", "--voxel", "1.0",
                   "--scan-resolution", "2", "--stop-fraction", "0.02", "--max-nbv", "2",
                   "--surface-samples", "2000", "--json", str(out), "--save", str(tmp_path / "vp.rrd")]) == 0
    res = json.loads(out.read_text())
    assert res["phase1"]["views"] >= 2 and res["phase1"]["boundary_coverage"] >= 0.95
    assert res["tour_length_m"] > 0
    rows = res["phase2"]
    assert 1 <= len(rows) <= 3
    assert set(res) == {"phase1", "phase2", "tour_length_m", "surface_in_sight"}
    assert rows[-1]["surface_coverage"] <= res["surface_in_sight"] <= 1
    assert set(res["phase1"]) == {"views", "boundary_coverage", "seconds"}
    keys = {"seen_occupied", "unseen", "boundary_unseen", "visible_to_nbv", "surface_coverage", "seconds", "stop"}
    assert all(set(r) == keys for r in rows)
    text = capsys.readouterr().out
    assert "Boundary unseen" in text and "in sight of some reachable view" in text
    assert (tmp_path / "vp.rrd").stat().st_size > 0


def test_vueplan_cli_phase1_only_with_floorplan(ibrnav_command, tmp_path, gl_ctx):
    from ibr.synthetic import make_world
    world = make_world("courtyard")
    mesh_path, plan_path = tmp_path / "site.ply", tmp_path / "site.wkt"
    world.mesh.export(mesh_path)
    plan_path.write_text(world.free_space.wkt)
    out = tmp_path / "p1.json"
    assert ibrnav_command(*["vueplan", str(mesh_path), "--floorplan", str(plan_path), "--phase1-only",
                   "--candidates", "200", "--json", str(out), "--save", str(tmp_path / "p1.rrd")]) == 0
    res = json.loads(out.read_text())
    assert res["phase2"] == [] and res["phase1"]["boundary_coverage"] >= 0.95


def test_vueplan_cli_bad_site(ibrnav_command, tmp_path):
    for site in ("synthetic:nowhere", str(tmp_path / "missing.obj")):
        with pytest.raises(InputError, match="nowhere|missing"):
            ibrnav_command(*["vueplan", site, "--save", str(tmp_path / "x.rrd")])
    with pytest.raises(InputError, match="--voxel"):
        ibrnav_command(*["vueplan", "synthetic:courtyard", "--voxel", "0", "--save", str(tmp_path / "x.rrd")])


@pytest.mark.parametrize("wkt,match", [
    ("POLYGON ((0 0, 0.4 0, 0.4 0.4, 0 0.4, 0 0))", "no free space"),  # narrower than the clearance
    # two separate yards: views that the roadmap cannot join
    ("MULTIPOLYGON (((0 0, 10 0, 10 10, 0 10, 0 0), (4 4, 6 4, 6 6, 4 6, 4 4)),"
     " ((20 0, 30 0, 30 10, 20 10, 20 0), (24 4, 26 4, 26 6, 24 6, 24 4)))", "cannot be reached")])
def test_vueplan_cli_unusable_floor_plans(ibrnav_command, tmp_path, wkt, match):
    from ibr.synthetic import make_world
    mesh_path, plan_path = tmp_path / "site.ply", tmp_path / "site.wkt"
    make_world("courtyard").mesh.export(mesh_path)
    plan_path.write_text(wkt)
    # no overlap constraint, so the greedy cover takes views in both yards
    with pytest.raises(InputError, match=match):
        ibrnav_command(*["vueplan", str(mesh_path), "--floorplan", str(plan_path), "--phase1-only",
                         "--overlap", "0", "--candidates", "100", "--save", str(tmp_path / "x.rrd")])
