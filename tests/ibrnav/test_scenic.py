"""`ibrnav scenic` end to end on a tiny run: JSON of per-frame metrics and a recording."""

import json

import pytest

from ibr.errors import InputError
from ibr.scene import SceneError
from ibrnav.commands.scenic import ScenicInputError

TINY = ["--frames", "2", "--width", "160", "--height", "120", "--particles", "40",
        "--nodes", "40", "--gt-samples", "2000"]


@pytest.mark.parametrize("agents,planner,matcher", [(2, "scenic", "dense"), (1, "rrtstar", "sift")])
def test_tiny_run_writes_metrics(ibrnav_command, tmp_path, agents, planner, matcher):
    out, rrd = tmp_path / "scenic.json", tmp_path / "scenic.rrd"
    assert ibrnav_command("scenic", "synthetic:office", "--agents", agents, "--planner", planner, "--seed", 1,
                          "--matcher", matcher, "--json", out, "--save", rrd, *TINY) == 0
    result = json.loads(out.read_text())
    assert set(result) == {"per_frame", "final"}
    frames = result["per_frame"]
    assert [f["frame"] for f in frames] == [0, 1, 2]
    keys = {"frame", "coverage", "outlier_ratio", "mean_error_m"}
    assert all(set(f) == keys for f in frames)
    for f in frames:
        assert 0.0 <= f["coverage"] <= 1.0 and 0.0 <= f["outlier_ratio"] <= 1.0
        assert 0.0 <= f["mean_error_m"] <= 0.05  # inliers are within d_i = 5 cm
    assert frames[0]["coverage"] > 0  # the initial pair reconstructed something
    assert result["final"] == frames[-1]
    assert rrd.stat().st_size > 10_000  # the recording is flushed before the command returns


def test_bad_arguments_are_input_errors(ibrnav_command, tmp_path):
    rrd = tmp_path / "x.rrd"
    for scene in ("strecha:/nowhere", "synthetic:nosuch", "synthetic:office?seed=x"):
        with pytest.raises(SceneError, match="synthetic:NAME|bad query"):
            ibrnav_command("scenic", scene, "--save", rrd, *TINY)
    assert issubclass(ScenicInputError, InputError) and issubclass(SceneError, InputError)
    with pytest.raises(ScenicInputError, match="--agents"):
        ibrnav_command("scenic", "synthetic:office", "--agents", "3", *TINY)
    with pytest.raises(ScenicInputError, match="--gamma"):
        ibrnav_command("scenic", "synthetic:office", "--gamma", "1.5", *TINY)
