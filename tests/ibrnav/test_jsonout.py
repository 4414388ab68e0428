"""Strict JSON: what the commands print and write parses with a parser that rejects NaN and
Infinity (RFC 8259), also when a query fails."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from ibrnav import jsonout


def strict_loads(text: str):
    def reject(name):
        raise ValueError(f"non-standard JSON constant {name}")
    return json.loads(text, parse_constant=reject)


def test_non_finite_numbers_become_null_recursively_numpy_included():
    value = {"a": float("inf"), "b": [1.5, float("nan"), -math.inf], "c": np.float32(np.nan),
             "d": np.array([1.0, np.inf]), "e": (np.int64(3), np.bool_(True)), 7: "seven"}
    assert strict_loads(jsonout.dumps(value)) == {"a": None, "b": [1.5, None, None], "c": None,
                                                  "d": [1.0, None], "e": [3, True], "7": "seven"}
    with pytest.raises(ValueError, match="Infinity"):
        strict_loads(json.dumps({"a": float("inf")}))  # the parser is strict: Python's default is not


def test_write_gives_the_same_text_as_dumps(tmp_path):
    text = jsonout.write(tmp_path / "x.json", {"x": [np.nan, 2]})
    assert (tmp_path / "x.json").read_text() == text + "\n"
    assert strict_loads(text) == {"x": [None, 2]}


@pytest.mark.slow
def test_eval_loc_with_queries_that_fail_writes_strict_json(tmp_path):
    """64x48 photos give PnP too few features: every query fails, its error is null and the
    row says why."""
    out = tmp_path / "loc.json"
    run = subprocess.run([sys.executable, "-m", "ibrnav", "-q", "eval-loc", "synthetic:office?views=3&width=64&height=48",
                          "--method", "pnp", "--model", "mesh", "--json", str(out), "--save", str(tmp_path / "x.rrd")],
                         capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    summary, full = strict_loads(run.stdout), strict_loads(out.read_text())
    assert summary["success_rate"] == 0.0 and summary["median_position_m"] is None
    assert {k: v for k, v in full.items() if k != "per_trial"} == summary
    for row in full["per_trial"]:
        assert row["position_m"] is None and row["rotation_deg"] is None and not row["success"]
        assert row["reason"]
