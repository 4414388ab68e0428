"""`ibrnav explore SCENE`: the SCENE spec is read like every other command's
(`synthetic:NAME[?seed=N]`), and a bad one is one line naming it, with no traceback."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

BIN = Path(sys.executable).parent


def ibrnav(*args):
    return subprocess.run([str(BIN / "ibrnav"), *map(str, args)], capture_output=True, text=True, timeout=600)


@pytest.mark.parametrize("spec", ["synthetic:nosuch?seed=3", "synthetic:office?seed=x", "synthetic:office?views=3"])
def test_a_bad_scene_spec_is_one_line_naming_it(spec):
    run = ibrnav("explore", spec)
    assert run.returncode == 2
    assert run.stderr.count("\n") == 1 and spec in run.stderr and "Traceback" not in run.stderr


def random_explore(tmp_path, spec: str, photos: int, achievable_poses: int) -> dict:
    """`ibrnav explore SPEC --strategy random` at a photo budget; its --json report."""
    out = tmp_path / "explore.json"
    run = ibrnav("explore", spec, "--strategy", "random", "--photos", photos, "--json", out,
                 "--achievable-poses", achievable_poses)
    assert run.returncode == 0, run.stderr
    return json.loads(out.read_text())


def test_more_far_goals_than_goals_is_one_line_naming_the_flag():
    run = ibrnav("explore", "synthetic:office", "--far-goals", 7, "--goals-per-round", 6)
    assert run.returncode == 2
    assert run.stderr.count("\n") == 1 and "--far-goals 7" in run.stderr and "Traceback" not in run.stderr


def test_retry_tilts_is_on_unless_turned_off():
    """By default (and with `--retry-tilts`) the mission has ASIFT's tilts for the photos plain
    SIFT cannot fix; with `--no-retry-tilts` it localises with plain SIFT alone."""
    import argparse

    from ibrnav.args import add_mission_args, mission_config
    from robot.mission.adaptive import ASIFT_TILTS

    parser = argparse.ArgumentParser()
    add_mission_args(parser, 261)
    assert mission_config(parser.parse_args([])).retry_tilts == ASIFT_TILTS
    assert mission_config(parser.parse_args(["--retry-tilts"])).retry_tilts == ASIFT_TILTS
    assert mission_config(parser.parse_args(["--no-retry-tilts"])).retry_tilts == ()


def test_bundle_adjustment_is_off_unless_turned_on():
    """By default the mission keeps its fixes' poses; `--bundle-adjust` adjusts the grown
    photos at each rebuild."""
    import argparse

    from ibrnav.args import add_mission_args, mission_config
    from robot.mission.bundle import BundleConfig

    parser = argparse.ArgumentParser()
    add_mission_args(parser, 261)
    assert mission_config(parser.parse_args([])).bundle is None
    assert mission_config(parser.parse_args(["--bundle-adjust"])).bundle == BundleConfig()


def test_keeping_off_met_surfaces_is_off_unless_turned_on():
    """By default the robot keeps off the surfaces its ultrasonic met only at its goals;
    `--keep-off-surfaces` keeps it off them on its way too."""
    import argparse

    from ibrnav.args import add_mission_args, mission_config

    parser = argparse.ArgumentParser()
    add_mission_args(parser, 261)
    assert not mission_config(parser.parse_args([])).keep_off_surfaces
    assert mission_config(parser.parse_args(["--keep-off-surfaces"])).keep_off_surfaces


def test_precise_seeds_are_off_unless_turned_on():
    """By default every vision fix poses its photo; `--precise-seeds` gates it on how far a
    shared error of its map points moves it (`PRECISE_SEEDS_M_PER_PX`)."""
    import argparse

    from ibrnav.args import add_mission_args, mission_config
    from robot.mission.adaptive import PRECISE_SEEDS_M_PER_PX

    parser = argparse.ArgumentParser()
    add_mission_args(parser, 261)
    assert mission_config(parser.parse_args([])).max_seed_m_per_px is None
    assert mission_config(parser.parse_args(["--precise-seeds"])).max_seed_m_per_px == PRECISE_SEEDS_M_PER_PX


def test_explore_runs_with_a_seeded_spec(tmp_path):
    report = random_explore(tmp_path, "synthetic:office?seed=3", 3, 0)
    assert report["scene"] == "synthetic:office?seed=3" and report["photos"] == 3


def test_explore_in_an_apartment_reports_rooms_and_why_it_stopped(tmp_path):
    report = random_explore(tmp_path, "synthetic:apartment?seed=5", 4, 80)
    assert report["stopped_because"] == "budget" and report["photos"] == report["random_photos"] == 4
    assert len(report["rooms"]) >= 2 and len(report["rooms_visited"]) == 1  # 4 photos: one circle, one room
    assert set(report["rooms_visited"]) <= set(report["rooms"])
    assert report["localization_error_m"] is None and report["map_scale_error"] is None  # no adaptive stage, no map
    assert report["localization_error_by_region_m"] is None and report["lost_photos"] is None
    assert report["localization_error_by_fix_m"] is None
    facing = report["facing_distance_m"]  # one circle in a room: every photo faces a wall 0-10 m ahead
    assert facing["adaptive"] is None and facing["random"]["photos"] == 4
    assert 0 < facing["random"]["p25"] <= facing["random"]["median"] <= facing["random"]["p75"] < 10
    assert report["model_photos_error"] is None
    assert report["localised_at_end"] is None  # no filter in a random capture
    assert report["pnp_fixes"] == report["pnp_failures"] == report["pnp_weak_fixes"] == 0
    assert report["pnp_failure_reasons"] == {}
    assert report["obstacles_met"] == {}  # nor its drives
    assert report["start_anchored"] is None and report["first_map_scale_error"] is None  # nor a first map
    assert report["coverage"] <= report["achievable_coverage"] <= 1


def test_floor_spans_are_off_unless_asked_for():
    """By default the first map keeps one floor factor (`MapConfig()` as it was); with
    `--floor-spans` it is placed by the floor's distances between its stops."""
    import argparse

    from ibrnav.args import add_mission_args, mission_config
    from robot.mission.map_building import MapConfig

    parser = argparse.ArgumentParser()
    add_mission_args(parser, 261)
    assert mission_config(parser.parse_args([])).map == MapConfig() and not MapConfig().floor_spans
    assert mission_config(parser.parse_args(["--floor-spans"])).map.floor_spans
