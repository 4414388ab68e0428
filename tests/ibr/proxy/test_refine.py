"""Pose refinement (`ibr.proxy.refine`): the frame alignment recovers a known similarity even
for cameras in a line; refining filter-like noisy poses of a robot's wall-facing photos moves
them towards the truth and reports how far they moved."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from ibr.camera import intrinsics_from_fov, rigid
from ibr.proxy.refine import RefineError, Refinement, align_frames, refine_poses


def test_align_frames_recovers_a_similarity_for_cameras_in_a_line():
    rng = np.random.default_rng(3)
    n = 9
    world_from_cam = np.array([rigid(Rotation.random(random_state=k).as_matrix(), [x, -2.5, 1.0])
                               for k, x in enumerate(np.linspace(-1.5, 1.5, n))])  # centres on a line
    s, R, t = 0.37, Rotation.random(random_state=7).as_matrix(), rng.normal(size=3)
    ba_from_world = np.linalg.inv(rigid(s * R, t))  # world = s R ba + t
    ba_from_cam = ba_from_world @ world_from_cam
    ba_from_cam[:, :3, :3] /= np.cbrt(np.linalg.det(ba_from_cam[:, :3, :3]))[:, None, None]  # rotations again
    ba_from_cam[4, :3, 3] += 5.0  # one camera the adjustment moved far: ignored
    s2, R2, t2 = align_frames(ba_from_cam, world_from_cam)
    assert s2 == pytest.approx(s, rel=1e-9)
    np.testing.assert_allclose(R2, R, atol=1e-9)
    np.testing.assert_allclose(t2, t, atol=1e-9)


def test_refine_moves_noisy_poses_towards_the_truth(office, gl_ctx):
    from robot.protocol import forward_camera_mount, robot_camera

    size = (320, 240)
    K, mount = intrinsics_from_fov(70, *size), forward_camera_mount(1.0)
    poses = np.array([(x, -2.5, np.pi / 2 + dh) for x in np.linspace(-1.5, 1.5, 5) for dh in (-0.35, 0.0, 0.35)])
    truth = [robot_camera(p, K, size, mount) for p in poses]
    images = [office.photograph(c) for c in truth]
    rng = np.random.default_rng(1)
    spacing = 3.0 / 4  # between stops, metres
    noisy_poses = poses + np.c_[rng.normal(0, 0.05 * spacing, (len(poses), 2)),
                                rng.normal(0, np.radians(1), len(poses))]
    noisy = [robot_camera(p, K, size, mount) for p in noisy_poses]
    try:
        res = refine_poses(noisy, images)
    except RefineError as e:  # a refinement that fails must say so, never a guess
        pytest.fail(f"refinement failed on a well-textured capture: {e}")
    error = lambda cams: np.median([np.linalg.norm(a.center - b.center) for a, b in zip(cams, truth)])
    assert error(res.cameras) < 0.7 * error(noisy)  # 8 seeds of a larger capture: 0.22-0.59
    report = res.report()
    moved = [np.linalg.norm(a.center - b.center) for a, b in zip(res.cameras, noisy)]
    assert report["moved_m_max"] == pytest.approx(max(moved))
    assert report["moved_m_median"] == pytest.approx(np.median(moved))
    assert report["reprojection_px_after"] < report["reprojection_px_before"]
    assert [c.name for c in res.cameras] == [c.name for c in noisy]


def test_the_report_names_cameras_that_moved_far():
    from ibr.camera import Camera

    cams = [Camera(np.eye(3), 4, 3, name=f"c{i}") for i in range(5)]
    moved, turned = np.array([0.01, 0.012, 0.011, 0.2, 0.009]), np.array([0.1, 0.1, 0.1, 0.1, 0.9])
    report = Refinement(cams, np.zeros((0, 3)), np.zeros((0, 3), np.uint8), moved, turned, 1.0, 0.2, []).report()
    assert report["moved_far"] == ["c3", "c4"]  # 18x the median distance; 9x the median turn
    assert report["moved_m_median"] == pytest.approx(0.011) and report["turned_deg_max"] == pytest.approx(0.9)
