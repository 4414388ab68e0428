"""GPU plane-sweep stereo: the filtered per-view depth of a synthetic textured scene matches
the true depth rendered from its mesh."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from ibr.camera import Camera, intrinsics_from_fov
from ibr.mesh_renderer import MeshRenderer
from ibr.proxy.plane_sweep import PlaneSweep, PlaneSweepConfig, consistency_filter
from ibr.scene import Scene, View

W, H = 160, 120


@pytest.fixture(scope="module")
def stereo_scene(gl_ctx, textured):
    """A textured wall 6 m ahead and a textured box 3-3.6 m ahead, seen by 4 cameras 0.3 m apart."""
    wall = trimesh.creation.box((12, 0.1, 8))
    wall.apply_translation((0, 6, 0))
    box = trimesh.creation.box((1.2, 0.6, 1.0))
    box.apply_translation((0.2, 3.3, -0.2))
    world = trimesh.util.concatenate([textured(wall, 0), textured(box.subdivide().subdivide(), 1)])
    K = intrinsics_from_fov(55, W, H)
    cams = [Camera.look_at((x, 0, 0), (x, 6, 0), K, W, H, name=f"c{i}")
            for i, x in enumerate((-0.45, -0.15, 0.15, 0.45))]
    renderer = MeshRenderer(world, gl_ctx)
    views = [View(c, renderer.render(c).color) for c in cams]
    true = np.stack([renderer.render(c).depth for c in cams])
    return Scene("stereo", views, mesh=world), true


def test_plane_sweep_depth_matches_truth(gl_ctx, stereo_scene):
    scene, true = stereo_scene
    cfg = PlaneSweepConfig(depth_range=(1.5, 10.0), planes=64, neighbours=2)
    sweep = PlaneSweep(scene, cfg, gl_ctx)
    depth, score = sweep.depth_maps()
    sweep.release()
    filtered = consistency_filter(scene, depth, score, cfg)
    for i in (1, 2):                                   # the inner views see both neighbours
        kept = filtered[i] > 0
        assert kept.mean() > 0.5
        rel = np.abs(filtered[i][kept] - true[i][kept]) / true[i][kept]
        assert np.median(rel) < 0.02
        on_box = kept & (true[i] < 4.0)                # the box's depth edge is found too
        assert on_box.sum() > 200 and np.median(np.abs(filtered[i][on_box] - true[i][on_box])) < 0.1


def test_consistency_filter_rejects_disagreeing_depths(stereo_scene):
    scene, true = stereo_scene
    cfg = PlaneSweepConfig()
    scores = np.ones_like(true)
    assert (consistency_filter(scene, true, scores, cfg)[1][true[1] > 0] > 0).mean() > 0.8
    wrong = true.copy()
    wrong[1] *= 1.2                                    # view 1 disagrees with everyone
    assert (consistency_filter(scene, wrong, scores, cfg)[1] > 0).mean() < 0.05


def test_dense_points_lie_on_the_surface(gl_ctx, stereo_scene):
    from ibr.proxy.dense_points import DenseConfig, dense_points

    scene, true = stereo_scene
    cam = scene.cameras[1]
    v, u = np.nonzero(true[1] > 0)
    sparse = cam.unproject(np.c_[u, v][::50].astype(float), true[1][v, u][::50])
    pts, cols, eyes = dense_points(scene, sparse, DenseConfig(scale=1.0, planes=64, stride=4))
    assert len(pts) > 1000 and cols.dtype == np.uint8 and eyes.shape == pts.shape
    _, dist, _ = trimesh.proximity.closest_point(scene.mesh, pts[::5])
    # metres, at 3-6 m: under a fifth of the plane spacing (64 planes uniform in inverse depth
    # over 2.3-7.8 m: 5.3 cm apart at the box, 17.5 cm at the wall). 1.4 cm when the photos
    # were rendered with llvmpipe's own (sharper) anisotropic sampler, 2.6 cm with the
    # renderer's standard footprint filter (`MeshRenderer.anisotropy`), 2.5 cm trilinear.
    assert np.median(dist) < 0.03
