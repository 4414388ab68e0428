"""COLMAP SfM in a child process, stopped for good at a time limit.

The re-posing (`robot.mission.repose`) maps every photo of a mission again, hundreds of
them, inside one step of a round. COLMAP's own stop (`max_runtime_seconds`) is checked only
between its registration steps, so a bundle adjustment of a large model ran on past it:
apartment 2's mission (920 photos, three missions sharing the 2 cores) was still inside one
`incremental_mapping` call, told to stop at 300 s, when the step's 600 s limit ended the
whole mission (`robot.mission.watchdog`). A call into a C library
cannot be interrupted from Python, but a process can be killed: `run_sfm_within` runs
`map_building.sfm_in_workspace` in a child Python and kills it at `limit_s`, so a slow
re-posing costs its round the re-posing, not the mission its photos.

The workspace stays usable after a kill: the photos are saved by the parent, features are
extracted for whatever the database lacks (`map_building._in_database`), COLMAP skips pairs
already matched, and the last model is replaced whole or not at all.
"""

from __future__ import annotations

import logging
import os
import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np

from robot.mission.map_building import MapConfig, MapError, save_images

log = logging.getLogger(__name__)

_JOB, _ERROR = "sfm_job.pkl", "sfm_error.txt"
_CHILD = "import sys; from pathlib import Path; from robot.mission.sfm_process import child; sys.exit(child(Path(sys.argv[1])))"


def run_sfm_within(images: list[np.ndarray], K: np.ndarray, config: MapConfig, work: Path, pairs: np.ndarray,
                   grow_only: bool, max_seconds: float | None, limit_s: float):
    """The largest model (pycolmap.Reconstruction) of `map_building.run_sfm(images, K, ...,
    config, work, pairs, grow_only, max_seconds)`, run in a child process; None when it had
    not finished after `limit_s` seconds (the child is killed; `work` keeps its features,
    matches and last model for the next call). Raises `MapError` as `run_sfm` does, and
    when the child dies some other way. The child is killed whenever this call ends early
    (the watchdog's `StepTimeout` included)."""
    import pycolmap

    work.mkdir(parents=True, exist_ok=True)
    names = save_images(images, work)
    (work / _ERROR).unlink(missing_ok=True)
    with open(work / _JOB, "wb") as f:
        pickle.dump((names, np.asarray(K), config, np.asarray(pairs), grow_only, max_seconds), f)
    root = str(Path(__file__).resolve().parents[2])  # the checkout this module was imported from
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (root, os.environ.get("PYTHONPATH")) if p)}
    child = subprocess.Popen([sys.executable, "-c", _CHILD, str(work)], env=env)
    try:
        rc = child.wait(timeout=max(limit_s, 1.0))
    except subprocess.TimeoutExpired:
        return None
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
    if rc == 0:
        return pycolmap.Reconstruction(work / "model")
    error = work / _ERROR
    raise MapError(error.read_text() if error.exists() else f"SfM's process ended with exit status {rc}")


def child(work: Path) -> int:
    """The child's side: the job `run_sfm_within` left in `work`; 0 with the model in
    `work`/model, 3 with the `MapError` in `work`/sfm_error.txt."""
    from robot.mission.map_building import sfm_in_workspace

    with open(work / _JOB, "rb") as f:
        names, K, config, pairs, grow_only, max_seconds = pickle.load(f)
    try:
        sfm_in_workspace(names, K, np.zeros(len(names)), config, work, pairs, grow_only, max_seconds)
    except MapError as e:
        (work / _ERROR).write_text(str(e))
        return 3
    return 0
