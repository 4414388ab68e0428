"""End-to-end runs of the `ibrnav` command as a user types it."""

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

BIN = Path(sys.executable).parent


def ibrnav(*args, cwd=None):
    return subprocess.run([str(BIN / "ibrnav"), *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, timeout=600)


def rrd_entities(rrd: Path) -> str:
    stats = subprocess.run([str(BIN / "rerun"), "rrd", "stats", str(rrd)], capture_output=True, text=True)
    assert stats.returncode == 0, stats.stderr
    return subprocess.run([str(BIN / "rerun"), "rrd", "print", str(rrd)], capture_output=True,
                          text=True).stdout


def test_demo_runs_the_capture_mission_into_a_recording_and_a_session(tmp_path):
    rrd, capture = tmp_path / "demo.rrd", tmp_path / "capture"
    run = ibrnav("demo", "--world", "office", "--random-photos", "40", "--circle-step-deg", "20", "--photos", "44", "--width", "240",
                 "--height", "180", "--max-rounds", "1", "--goals-per-round", "2", "--tour-frames", "2",
                 "--session", capture, "--save", rrd)
    assert run.returncode == 0, run.stderr
    captured = int(re.search(r"captured (\d+) photos", run.stdout).group(1))
    assert 40 <= captured <= 44  # the budget, less 2 photos per goal given up in the one round (COLMAP
    # varies from run to run: in some runs both goals of the round are given up)
    assert "initial map:" in run.stderr and "round 1:" in run.stderr  # progress on stderr
    printed = rrd_entities(rrd)
    for entity in ("/world/robot/camera/image", "/world/robot", "/world/estimate", "/world/map/points",
                   "/world/map/mesh", "/world/nbv/candidates", "/world/plan/grid", "/world/plan/sonar",
                   "/world/plan/path",
                   "/world/tour/camera/image", "plots/coverage", "plots/estimate_error_m",
                   "/world/particles", "plots/dead_reckoning_error_m"):
        assert entity in printed, entity
    log = [json.loads(line) for line in (capture / "log.jsonl").read_text().splitlines()]
    photos = [r for r in log if r["kind"] == "photo"]
    assert sum(r["stage"] != "localise" for r in photos) == captured
    assert len(list((capture / "photos").glob("*.png"))) == len(photos)
    from ibr.scene import load_scene  # the capture folder is a scene: the final model it wrote

    scene = load_scene(capture)
    assert scene.meta["poses"] == "model" and len(scene) >= 20 and scene.mesh is not None


def test_drive_records_to_a_default_file_without_flags(tmp_path):
    run = ibrnav("drive", "--max-legs", "2", "--width", "32", "--height", "24", cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    assert (tmp_path / "ibrnav_drive.rrd").stat().st_size > 0


def test_scene_show_logs_cameras_and_geometry(tmp_path, strecha_dir):
    rrd = tmp_path / "scene.rrd"
    run = ibrnav("scene", "show", strecha_dir / "Herz-Jesus-P8", "--save", rrd)
    assert run.returncode == 0, run.stderr
    assert "8 views" in run.stdout
    assert "/world/cameras/0003_jpg/image" in rrd_entities(rrd)


def test_bad_scene_is_one_clear_line(tmp_path):
    run = ibrnav("scene", "show", tmp_path / "missing", "--save", tmp_path / "x.rrd")
    assert run.returncode == 2
    assert "missing: no such scene folder" in run.stderr
    assert "Traceback" not in run.stderr


@pytest.mark.slow
def test_bench_writes_json(tmp_path):
    out = tmp_path / "bench.json"
    run = ibrnav("bench", "--only", "mesh_views_per_s_64x48", "--json", out)
    assert run.returncode == 0, run.stderr
    assert json.loads(run.stdout) == json.loads(out.read_text())  # stdout is the JSON alone
    fig = json.loads(out.read_text())["figures"]["mesh_views_per_s_64x48"]
    assert set(fig) == {"value", "unit", "baseline", "ratio"}
    assert fig["ratio"] == pytest.approx(fig["value"] / fig["baseline"])


def test_bench_knows_the_figures_of_every_package():
    from ibrnav.bench import all_figures, bench_modules

    assert bench_modules() == ["ibr.bench", "ibr.render.bench", "localization.bench", "explore.bench",
                               "explore.scenic.bench", "explore.vueplan.bench", "robot.mission.bench"]
    assert set(all_figures()) == {
        "mesh_views_per_s_64x48", "ulr_fps_640x480_10src", "particle_likelihoods_per_s_64x48", "pnp_s_per_query",
        "pf_seconds_per_query",
        "heuristic_evals_per_s_100src_64x48", "heuristic_evals_per_s_100src_160x120", "astar_s_100x100",
        "astar_s_1000x1000", "scenic_nbv_poses_per_s", "vueplan_phase2_s_per_nbv", "vueplan_phase1_s_500",
        "first_map_again_s"}


def test_version_and_quiet_flags():
    run = ibrnav("--version")
    assert run.returncode == 0 and run.stdout.startswith("ibrnav ")
    run = ibrnav("-q", "explore", "synthetic:nowhere")
    assert run.returncode == 2 and "synthetic:nowhere" in run.stderr  # errors are shown even when quiet
