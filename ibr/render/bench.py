"""Speed figure of the unstructured lumigraph renderer (see `ibrnav bench`): frames/s of the
GL renderer at 640x480 blending 10 source photos (proxy pass, per-pixel k-best blend, hole
filling, read-back) vs the numpy reference of the same blend (`ulr_blend_numpy`) on the same
frame, given the surface points for free."""

from __future__ import annotations

import dataclasses

import numpy as np

from ibr.bench import best_seconds
from ibr.scene import load_scene
from ibr.render.ulr import UlrRenderer, fill_depth_holes, ulr_blend_numpy


def ulr_fps_640x480_10src() -> dict:
    """ULR frames/s at 640x480 with 10 sources (synthetic office, true mesh as proxy): the
    view is one photo of a 21-photo ring, the sources its ten nearest neighbours, which cover
    about 90% of it (a sparser ring leaves the frame nearly empty, and the figure would time
    the source tests alone)."""
    scene = load_scene("synthetic:office?views=21&width=640&height=480")
    held = scene.views[10]
    sources = dataclasses.replace(scene, views=scene.views[5:10] + scene.views[11:16])
    renderer = UlrRenderer(sources, scene.mesh, k=4)
    cam = held.camera
    gl_s = best_seconds(lambda: renderer.render_frame(cam), repeats=5)
    view_depth = fill_depth_holes(renderer.proxy_depth(cam))
    z = np.abs(view_depth).ravel()
    m = z > 0
    P = cam.unproject(cam.pixel_grid()[m], z[m])
    images = np.stack([v.image for v in sources.views])
    numpy_s = best_seconds(lambda: ulr_blend_numpy(
        P, view_depth.ravel()[m] > 0, cam.center, renderer.sources.matrices, renderer.sources.centres,
        images, renderer.source_depths, renderer.cfg), repeats=1)
    renderer.release()
    return {"value": 1.0 / gl_s, "unit": "frames/s", "baseline": 1.0 / numpy_s, "ratio": numpy_s / gl_s}


FIGURES = {"ulr_fps_640x480_10src": ulr_fps_640x480_10src}
