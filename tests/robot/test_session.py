"""Capture sessions: records and photos survive a kill at any point; reopening repairs torn
lines and orphans; a session loads as a Scene with cameras at the logged poses."""

import json
import os
import signal
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from ibr.camera import intrinsics_from_fov
from ibr.errors import InputError
from robot.protocol import Photo, forward_camera_mount
from robot.session import KILL_ENV, CaptureSession, SessionError, load_session_scene

K = intrinsics_from_fov(60, 32, 24)
MOUNT = forward_camera_mount(0.3)


def photo(i):
    img = np.zeros((24, 32, 3), np.uint8)
    img[..., 0], img[..., 1] = i, np.arange(32)[None, :]
    return Photo(img, 0.5 * i, np.array([0.1 * i, 0.0, 0.0]), 0.01 * i, 1.0 + i, i)


def fill(session, n):
    for i in range(n):
        session.append("sensor", step=i, range_m=1.0 + i)
        session.add_photo(photo(i), pose=np.array([0.1 * i, 0.2, 0.3 * i]), step=i)
        session.commit(i, {"i": i})


def test_records_and_photos_round_trip(tmp_path):
    with CaptureSession.create(tmp_path / "s", K, (32, 24), MOUNT, {"seed": 1}) as s:
        fill(s, 3)
    s = CaptureSession.open(tmp_path / "s")
    assert [r["seq"] for r in s.records] == list(range(9))
    assert [r["index"] for r in s.photos] == [0, 1, 2] and s.recovery == {}
    assert s.last_commit["state"] == {"i": 2}
    scene = load_session_scene(tmp_path / "s")
    assert len(scene) == 3
    assert np.array_equal(scene.views[2].image, photo(2).image)  # lossless


def test_session_loads_as_a_scene_with_cameras_at_the_logged_poses(tmp_path):
    with CaptureSession.create(tmp_path / "s", K, (32, 24), MOUNT) as s:
        fill(s, 2)
    scene = load_session_scene(tmp_path / "s")
    cam = scene.views[1].camera
    x, y, th = 0.1, 0.2, 0.3
    # forward_camera_mount(0.3): 5 cm ahead of the axle, 0.3 m up, looking along the heading
    assert np.allclose(cam.center, [x + 0.05 * np.cos(th), y + 0.05 * np.sin(th), 0.3])
    assert np.allclose(cam.forward, [np.cos(th), np.sin(th), 0])
    assert np.allclose(cam.K, K) and (cam.width, cam.height) == (32, 24)
    assert scene.views[1].name == "photo_00001"


def test_torn_last_line_orphans_and_temps_are_repaired(tmp_path):
    folder = tmp_path / "s"
    with CaptureSession.create(folder, K, (32, 24), MOUNT) as s:
        fill(s, 2)
    with open(folder / "log.jsonl", "ab") as f:
        f.write(b'{"seq":6,"kind":"pho')  # killed mid-write
    (folder / "photos" / ".photo_00002.png.tmp").write_bytes(b"half an image")
    (folder / "photos" / "photo_00002.png").write_bytes((folder / "photos" / "photo_00001.png").read_bytes())
    s = CaptureSession.open(folder)
    assert s.recovery == {"torn_bytes": 20, "temp_files": ["photos/.photo_00002.png.tmp"],
                          "orphan_photos": ["photos/photo_00002.png"]}
    assert len(s.records) == 6 and sorted(p.name for p in (folder / "photos").iterdir()) == \
        ["photo_00000.png", "photo_00001.png"]
    s.add_photo(photo(2))  # appending goes on with the right numbers
    s.close()
    lines = (folder / "log.jsonl").read_text().splitlines()
    assert json.loads(lines[-1])["seq"] == 6 and json.loads(lines[-1])["file"] == "photos/photo_00002.png"


def test_rollback_drops_an_unfinished_step(tmp_path):
    folder = tmp_path / "s"
    with CaptureSession.create(folder, K, (32, 24), MOUNT) as s:
        fill(s, 2)
        s.append("sensor", step=2)
        s.add_photo(photo(2), step=2)  # step 2 never committed
    s = CaptureSession.open(folder, rollback=True)
    assert s.recovery["rolled_back"] == 2 and s.recovery["orphan_photos"] == ["photos/photo_00002.png"]
    assert s.records[-1]["kind"] == "commit" and len(s.photos) == 2
    assert len((folder / "log.jsonl").read_text().splitlines()) == 6


def test_bad_folders_are_clear_errors(tmp_path):
    with pytest.raises(SessionError, match="not a capture session") as e:
        CaptureSession.open(tmp_path)
    assert isinstance(e.value, InputError)
    folder = tmp_path / "s"
    with CaptureSession.create(folder, K, (32, 24), MOUNT) as s:
        fill(s, 2)
        with pytest.raises(SessionError, match="64x48"):
            s.add_photo(Photo(np.zeros((48, 64, 3), np.uint8), 0, np.zeros(3), 0, 0, 0))
    with pytest.raises(SessionError, match="already holds"):
        CaptureSession.create(folder, K, (32, 24), MOUNT)
    with pytest.raises(SessionError, match="another camera"):
        CaptureSession.open_or_create(folder, K * 2, (32, 24), MOUNT)
    (folder / "photos" / "photo_00000.png").unlink()
    with pytest.raises(SessionError, match="photo_00000.png"):
        CaptureSession.open(folder)
    lines = (folder / "log.jsonl").read_bytes().split(b"\n")
    lines[1] = b"{not json"
    (folder / "log.jsonl").write_bytes(b"\n".join(lines))
    with pytest.raises(SessionError, match="line 2 is corrupt"):
        CaptureSession.open(folder)


WRITER = textwrap.dedent("""
    import sys
    import numpy as np
    from ibr.camera import intrinsics_from_fov
    from robot.protocol import Photo, forward_camera_mount
    from robot.session import CaptureSession
    K, MOUNT = intrinsics_from_fov(60, 32, 24), forward_camera_mount(0.3)  # as K, MOUNT above
    def photo(i):  # as photo() above
        img = np.zeros((24, 32, 3), np.uint8)
        img[..., 0], img[..., 1] = i, np.arange(32)[None, :]
        return Photo(img, 0.5 * i, np.array([0.1 * i, 0.0, 0.0]), 0.01 * i, 1.0 + i, i)
    with CaptureSession.open_or_create(sys.argv[1], K, (32, 24), MOUNT, rollback=True) as s:
        done = s.last_commit["step"] + 1 if s.last_commit else 0
        for i in range(done, 4):
            s.append("sensor", step=i, range_m=1.0 + i)
            s.add_photo(photo(i), pose=np.array([0.1 * i, 0.2, 0.3 * i]), step=i)
            s.commit(i, {"i": i})
""")


@pytest.mark.parametrize("stage", ["image", "photo", "log"])
def test_killed_writer_resumes_with_nothing_lost_or_duplicated(tmp_path, stage):
    script = WRITER
    ref, run = tmp_path / "ref", tmp_path / "run"
    subprocess.run([sys.executable, "-c", script, str(ref)], check=True, timeout=60)
    env = dict(os.environ, **{KILL_ENV: f"4:{stage}"})  # record 4 is step 1's photo
    killed = subprocess.run([sys.executable, "-c", script, str(run)], env=env, timeout=60)
    assert killed.returncode == -signal.SIGKILL
    subprocess.run([sys.executable, "-c", script, str(run)], check=True, timeout=60)
    assert (run / "log.jsonl").read_bytes() == (ref / "log.jsonl").read_bytes()
    names = sorted(p.name for p in (ref / "photos").iterdir())
    assert names == sorted(p.name for p in (run / "photos").iterdir()) and len(names) == 4
    for n in names:
        assert (run / "photos" / n).read_bytes() == (ref / "photos" / n).read_bytes()
