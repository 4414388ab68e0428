"""Sweeps of the capture mission (`robot.mission.sweep`, `ibrnav eval-missions`): the worlds a
spec names, each mission's report read against the issue's bars, the counts over a sweep, and
a runner that keeps what it has and goes on where it stopped."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

from ibrnav.cli import main
from robot.mission.sweep import (compare, explore_command, load_reports, mission_bars, parse_worlds, run_sweep,
                                 summarise)


def _report(median=0.03, p95=0.12, heading=0.5, scale=0.004, visited=("a", "b"), rooms=("a", "b"), reached=45,
            given_up=3, seconds=200.0, coverage=0.60, achievable=0.65, lost=10, obstacles=(20, 5, 2)):
    return {"strategy": "adaptive", "localization_error_m": {"median": median, "p95": p95},
            "heading_error_deg": {"median": heading}, "map_scale_error": scale, "rooms_visited": list(visited),
            "rooms": list(rooms), "goals_reached": reached, "goals_given_up": given_up, "seconds": seconds,
            "coverage": coverage, "achievable_coverage": achievable, "stopped_because": "budget",
            "lost_photos": {"lost": lost}, "obstacles_met": dict(zip(("path", "side step", "recovery"), obstacles))}


def test_a_worlds_spec_names_each_world_and_seed():
    assert parse_worlds("apartment:0-2,office:4") == [("apartment", 0), ("apartment", 1), ("apartment", 2),
                                                      ("office", 4)]
    assert parse_worlds("apartment:1,3") == [("apartment", 1), ("apartment", 3)]
    for bad in ("3", "apartment:2-1", "apartment:x", ""):
        with pytest.raises(ValueError, match="--worlds"):
            parse_worlds(bad)


def test_a_mission_is_read_against_the_bars():
    """A mission that meets every bar, and one that misses the p95 (16 cm), a room, the goals
    (6 of 50 given up) and its coverage over random (0.60 against 0.50) and of the achievable
    (0.60 of 0.70, 86 %); a bar the report cannot say is None."""
    good = mission_bars(_report(), {"coverage": 0.40})
    assert all(good.values()), good
    bad = mission_bars(_report(p95=0.16, visited=("a",), reached=44, given_up=6, achievable=0.70), {"coverage": 0.50})
    assert {k for k, v in bad.items() if v is False} == {"p95", "rooms", "given_up", "over_random", "of_achievable"}
    alone = mission_bars(_report(rooms=(), visited=(), achievable=None))
    assert alone["over_random"] is None and alone["of_achievable"] is None and alone["rooms"] is None


def test_a_sweep_counts_the_worlds_that_meet_each_bar_and_names_the_worst():
    reports = {"apartment_0": _report(p95=0.30), "apartment_0.random": {"strategy": "random", "coverage": 0.3},
               "office_1": _report(p95=0.10, seconds=400.0)}
    s = summarise(reports)
    assert set(s["missions"]) == {"apartment_0", "office_1"}
    assert s["missions"]["apartment_0"]["random_coverage"] == 0.3
    assert s["bars_met"]["p95"] == {"met": 1, "of": 2} and s["bars_met"]["seconds"] == {"met": 1, "of": 2}
    assert s["bars_met"]["over_random"] == {"met": 1, "of": 1}
    assert s["spread"]["p95_m"] == {"median": pytest.approx(0.20), "worst": 0.30, "worst_mission": "apartment_0"}
    pairs = compare(reports, {**reports, "office_1": _report(p95=0.08, lost=4, obstacles=(3, 1, 0))})
    assert pairs["office_1"]["p95_m"] == [0.10, 0.08] and pairs["office_1"]["lost_photos"] == [10, 4]
    assert pairs["office_1"]["obstacles"] == [27, 4]


def _fake_explore(world, seed, strategy, out, options, seed_offset=0):
    """A stand-in for `ibrnav explore`: writes a report, or fails for office 1."""
    name = f"{world}_{seed}" + ("" if strategy == "adaptive" else f".{strategy}")
    code = (f"import json, sys; print('mission {name}'); sys.exit(3) if {world == 'office' and seed == 1} else "
            f"json.dump({{'strategy': '{strategy}', 'coverage': 0.5, 'options': {options!r}, "
            f"'mission_seed': {seed + seed_offset}}}, "
            f"open(r'{out / (name + '.json')}', 'w'))")
    return [sys.executable, "-c", code]


def test_the_runner_keeps_each_mission_and_goes_on_where_it_stopped(tmp_path):
    worlds = [("apartment", 0), ("apartment", 1), ("office", 1)]
    failed = run_sweep(worlds, tmp_path, ["--photos", "30"], jobs=2, strategies=("adaptive", "random"),
                       command=_fake_explore)
    assert sorted(failed) == ["office_1", "office_1.random"]
    assert "mission office_1" in (tmp_path / "office_1.log").read_text()
    reports = load_reports(tmp_path)
    assert set(reports) == {"apartment_0", "apartment_1", "apartment_0.random", "apartment_1.random"}
    assert reports["apartment_0"]["options"] == ["--photos", "30"] and reports["apartment_1"]["mission_seed"] == 1
    (tmp_path / "apartment_1.json").write_text(json.dumps({"strategy": "adaptive", "coverage": 0.9}))
    run_sweep(worlds, tmp_path, [], command=_fake_explore)  # office 1 tried again; the others are kept
    assert load_reports(tmp_path)["apartment_1"]["coverage"] == 0.9
    run_sweep(worlds, tmp_path / "again", [], command=_fake_explore, seed_offset=100)  # a second draw
    assert load_reports(tmp_path / "again")["apartment_1"]["mission_seed"] == 101


def test_a_mission_draws_from_its_own_seed_and_its_world_from_the_worlds():
    cmd = explore_command("apartment", 3, "adaptive", Path("out"), ["--photos", "30"], seed_offset=100)
    assert cmd[cmd.index("explore") + 1] == "synthetic:apartment?seed=3" and cmd[cmd.index("--seed") + 1] == "103"
    assert cmd[-2:] == ["--photos", "30"] and cmd[cmd.index("--json") + 1] == str(Path("out") / "apartment_3.json")


def test_eval_missions_reads_a_folder_and_names_a_bad_one(tmp_path, capsys):
    (tmp_path / "apartment_0.json").write_text(json.dumps(_report(p95=0.30)))
    (tmp_path / "office_0.json").write_text(json.dumps(_report()))
    assert main(["eval-missions", "--out", str(tmp_path), "--summary-only", "--worlds", "apartment:0,office:0-1",
                 "--baseline", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "| apartment_0 | 3.0 | 30.0 |" in out and "p95: met on 1 of 2" in out and "30.0 → 30.0" in out
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["bars_met"]["p95"] == {"met": 1, "of": 2} and summary["jobs"] == 1
    assert main(["eval-missions", "--out", str(tmp_path / "none"), "--summary-only"]) == 2
    assert "no such folder" in capsys.readouterr().err
    (tmp_path / "office_0.json").write_text("{not json")
    assert main(["eval-missions", "--out", str(tmp_path), "--summary-only"]) == 2
    assert "office_0.json: not an explore report" in capsys.readouterr().err


def test_explore_flags_reach_every_mission_and_a_bad_one_runs_none(tmp_path, capsys, monkeypatch):
    import robot.mission.sweep as sweep

    seen = []
    monkeypatch.setattr(sweep, "run_sweep", lambda worlds, out, options, *a, **k: seen.append(options) or [])
    (tmp_path / "office_0.json").write_text(json.dumps(_report()))
    args = ["eval-missions", "--worlds", "office:0", "--out", str(tmp_path)]
    assert main([*args, "--explore-flags=--bundle-adjust --max-rounds 3"]) == 0
    assert seen[0][-3:] == ["--bundle-adjust", "--max-rounds", "3"] and "--photos" in seen[0]
    assert json.loads((tmp_path / "summary.json").read_text())["mission_seed_offset"] == 0
    for flags, says in [("--bundel-adjust", "not flags of `ibrnav explore`: --bundel-adjust"),
                        ("--max-rounds x", "invalid int value"), ("--seed 3", "--seed is set by eval-missions"),
                        ("--phot 3", "not flags of `ibrnav explore`: --phot")]:
        assert main([*args, f"--explore-flags={flags}"]) == 2
        assert says in capsys.readouterr().err
    assert len(seen) == 1


def test_a_real_sweep_of_one_small_mission(tmp_path, capsys):
    """`ibrnav eval-missions` runs `ibrnav explore` and reads its real report: every figure the
    bars read is there (a key explore renamed would read as None here), the random arm beside it."""
    assert main(["eval-missions", "--worlds", "office:0", "--photos", "40", "--random-photos", "24",
                 "--achievable-poses", "200", "--eval-poses", "0", "--random", "--out", str(tmp_path)]) == 0
    m = json.loads((tmp_path / "summary.json").read_text())["missions"]["office_0"]
    for key in ("median_m", "p95_m", "heading_deg", "scale", "rooms", "seconds", "coverage", "achievable",
                "random_coverage", "stopped_because"):
        assert m[key] is not None, key
    assert m["bars"]["rooms"] is True and m["stopped_because"] == "budget"
    assert "| office_0 |" in capsys.readouterr().out
