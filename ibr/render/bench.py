"""Speed figure of the unstructured lumigraph renderer (see `ibrnav bench`): frames/s of the
GL renderer at 640x480 blending 10 source photos (proxy pass, blend, hole filling, read-back)
with Buehler et al.'s sparse blending field (the default, `UlrConfig.blending="field"`) vs
the per-pixel ULR (the quality reference) on the same frame, and, for reference, the numpy
blend of the same pixels (`ulr_blend_numpy`, given the surface points for free). Beside the
wall-clock figures, the CPU seconds per frame (every thread of the process, llvmpipe's
included), which a loaded machine inflates less than wall time."""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ibr.bench import best_seconds
from ibr.scene import load_scene
from ibr.render.ulr import UlrConfig, UlrRenderer, fill_depth_holes, ulr_blend_numpy


def _timed(fn, repeats: int = 5) -> tuple[float, float]:
    """(least wall seconds of `repeats` calls, after a warm-up; mean CPU seconds per call)."""
    cpu = time.process_time()
    wall = best_seconds(fn, repeats=repeats)
    return wall, (time.process_time() - cpu) / (repeats + 1)


def ulr_fps_640x480_10src() -> dict:
    """ULR frames/s at 640x480 with 10 sources (synthetic office, true mesh as proxy): the
    view is one photo of a 21-photo ring, the sources its ten nearest neighbours, which cover
    about 90% of it (a sparser ring leaves the frame nearly empty, and the figure would time
    the source tests alone). Baseline: the per-pixel ULR; ratio = field fps / per-pixel fps."""
    scene = load_scene("synthetic:office?views=21&width=640&height=480")
    held = scene.views[10]
    sources = dataclasses.replace(scene, views=scene.views[5:10] + scene.views[11:16])
    cam = held.camera
    out = {}
    for blending in ("field", "pixel"):
        renderer = UlrRenderer(sources, scene.mesh, config=UlrConfig(k=4, blending=blending))
        out[blending] = _timed(lambda: renderer.render_frame(cam))
        if blending == "pixel":
            view_depth = fill_depth_holes(renderer.proxy_depth(cam))
            z = np.abs(view_depth).ravel()
            m = z > 0
            P = cam.unproject(cam.pixel_grid()[m], z[m])
            images = np.stack([v.image for v in sources.views])
            numpy_s = best_seconds(lambda: ulr_blend_numpy(
                P, view_depth.ravel()[m] > 0, cam.center, renderer.sources.matrices, renderer.sources.centres,
                images, renderer.source_depths, renderer.cfg), repeats=1)
        renderer.release()
    (field_s, field_cpu), (pixel_s, pixel_cpu) = out["field"], out["pixel"]
    return {"value": 1.0 / field_s, "unit": "frames/s", "baseline": 1.0 / pixel_s, "ratio": pixel_s / field_s,
            "cpu_ms_per_frame": 1e3 * field_cpu, "baseline_cpu_ms_per_frame": 1e3 * pixel_cpu,
            "cpu_ratio": pixel_cpu / field_cpu, "numpy_blend_fps": 1.0 / numpy_s}


FIGURES = {"ulr_fps_640x480_10src": ulr_fps_640x480_10src}
