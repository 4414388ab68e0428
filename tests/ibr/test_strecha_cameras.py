"""The Strecha ground-truth cameras, read through `Camera.from_strecha_file`, explain real
SIFT matches: triangulated points reproject with sub-half-pixel median error."""

import cv2
import numpy as np

from ibr.scene import load_scene


def projection(cam):
    return cam.K @ cam.cam_from_world[:3, :]


def fundamental(a, b):
    """F with x_b^T F x_a = 0, from two calibrated cameras."""
    T = b.cam_from_world @ a.world_from_cam
    R, t = T[:3, :3], T[:3, 3]
    tx = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
    return np.linalg.inv(b.K).T @ tx @ R @ np.linalg.inv(a.K)


def test_fountain_4_5_reprojection(strecha_dir):
    scene = load_scene(strecha_dir / "fountain-P11")
    a, b = scene.view("0004.jpg"), scene.view("0005.jpg")
    sift = cv2.SIFT_create(4000)
    ka, da = sift.detectAndCompute(cv2.cvtColor(a.image, cv2.COLOR_RGB2GRAY), None)
    kb, db = sift.detectAndCompute(cv2.cvtColor(b.image, cv2.COLOR_RGB2GRAY), None)
    matches = [m for m, n in cv2.BFMatcher().knnMatch(da, db, k=2) if m.distance < 0.75 * n.distance]
    xa = np.float64([ka[m.queryIdx].pt for m in matches])
    xb = np.float64([kb[m.trainIdx].pt for m in matches])
    # epipolar gating with the *given* cameras: mismatches go, the cameras are not fitted
    F = fundamental(a.camera, b.camera)
    la = np.c_[xa, np.ones(len(xa))] @ F.T
    dist = np.abs(np.sum(la * np.c_[xb, np.ones(len(xb))], axis=1)) / np.hypot(la[:, 0], la[:, 1])
    keep = dist < 3.0
    assert keep.sum() > 500, "too few matches survive the ground-truth epipolar geometry"
    X = cv2.triangulatePoints(projection(a.camera), projection(b.camera), xa[keep].T, xb[keep].T)
    X = (X[:3] / X[3]).T
    err = np.r_[np.linalg.norm(a.camera.project(X)[0] - xa[keep], axis=1),
                np.linalg.norm(b.camera.project(X)[0] - xb[keep], axis=1)]
    assert np.median(err) < 0.5, np.median(err)
