"""The mapped share against a world's true mesh, with known answers: a query looking where
two map photos look from nearly the same place is mapped; a wall only one map photo sees, a
pair too far apart to match, or a view of the sky, is not."""

import numpy as np
import trimesh

from ibr.camera import Camera
from localization.mapped_share import MappedShare

K = np.array([[80.0, 0, 79.5], [0, 80.0, 59.5], [0, 0, 1]])


def camera(eye, target, name="c") -> Camera:
    return Camera.look_at(eye, target, K, 160, 120, name=name)


def wall() -> trimesh.Trimesh:
    """A 20 x 20 m wall in the plane y = 5 (world metres), filling the views below."""
    return trimesh.Trimesh([[-10, 5, -10], [10, 5, -10], [10, 5, 10], [-10, 5, 10]], [[0, 1, 2], [0, 2, 3]])


def test_a_view_two_near_map_photos_see_is_mapped_and_one_photo_alone_is_not(gl_ctx):
    query = camera([0.2, 0, 0], [0.2, 5, 0])
    pair = [camera([0, 0, 0], [0, 5, 0], "a"), camera([0.5, 0, 0], [0.5, 5, 0], "b")]
    share = MappedShare(wall(), pair, ctx=gl_ctx)
    assert share(query) > 0.9  # all but the strips at its edges only one map photo sees
    share.release()
    alone = MappedShare(wall(), pair[:1], ctx=gl_ctx)
    assert alone(query) == 0.0
    alone.release()


def test_map_photos_too_far_apart_to_match_do_not_map_the_wall(gl_ctx):
    # 6 m apart at 5 m from the wall: their rays meet at 60 degrees, beyond SIFT's matching
    wide = [camera([-3, 0, 0], [0, 5, 0], "a"), camera([3, 0, 0], [0, 5, 0], "b")]
    share = MappedShare(wall(), wide, ctx=gl_ctx)
    assert share(camera([0, 0, 0], [0, 5, 0])) < 0.05
    share.release()


def test_a_view_of_nothing_is_not_mapped(gl_ctx):
    pair = [camera([0, 0, 0], [0, 5, 0], "a"), camera([0.5, 0, 0], [0.5, 5, 0], "b")]
    share = MappedShare(wall(), pair, ctx=gl_ctx)
    assert share(camera([0, 0, 0], [0, -5, 0])) == 0.0
    share.release()


def test_every_photo_of_the_courtyards_default_ring_has_a_neighbour_that_can_match_it(gl_ctx):
    """The surface at the centre of each default photo of the courtyard is seen, unoccluded,
    by another default photo within 30 degrees (SIFT's reach). The old evenly spaced ring of
    24 left 10 photos per seed with none: those near a building."""
    from ibr.synthetic import make_world

    for seed in (0, 3):
        world = make_world("courtyard", seed)
        cams = world.default_cameras(world.default_view_count(), 160, 120)
        share = MappedShare(world.mesh, cams, ctx=gl_ctx)
        centres = []
        for c in cams:  # a photo looking across open ground has the sky at its centre
            g = share.renderer.render(c)
            centres.append(g.world[60, 80] if g.mask[60, 80] else np.full(3, np.nan))
        centres = np.array(centres)
        seen = share.seen(np.nan_to_num(centres))
        assert np.isfinite(centres[:, 0]).sum() > 0.8 * len(cams)
        for n, c in enumerate(cams):
            if np.isnan(centres[n, 0]):
                continue
            rays = centres[n] - np.array([m.center for m in cams])
            rays /= np.linalg.norm(rays, axis=1, keepdims=True)
            angles = np.degrees(np.arccos(np.clip(rays @ rays[n], -1.0, 1.0)))
            others = [angles[m] for m in range(len(cams)) if m != n and seen[m, n]]
            assert others and min(others) < 30.0, (seed, c.name)
        share.release()
