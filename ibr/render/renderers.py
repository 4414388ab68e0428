"""The renderer factory: every image-based renderer of ibr over one proxy mesh, by name, and
the proxy a scene gets ("mesh": its own; "photos": triangulated from its photos; "dense": with
plane-sweep points too). `ibrnav render`, `ibrnav eval-ibr` and the evaluation use these, so
every caller builds a method the same way."""

from __future__ import annotations

from ibr.errors import InputError
from ibr.proxy.dense_points import DenseConfig
from ibr.proxy.proxy_geometry import ProxyConfig, build_proxy
from ibr.render.depth_maps import render_depth_maps
from ibr.render.lightfield import LightFieldConfig, LightFieldRenderer
from ibr.render.nearest_view import NearestViewRenderer
from ibr.render.ulr import UlrConfig, UlrRenderer
from ibr.scene import Scene

METHODS = ("ulr", "ulr_pixel", "nearest", "lightfield", "lightfield_local")
"""ulr: unstructured lumigraph rendering with Buehler et al.'s sparse blending field (fast);
ulr_pixel (CLI ulr-pixel): the same weights evaluated at every pixel (the quality reference)."""
PROXIES = ("photos", "dense", "mesh")


class RendererError(InputError):
    """A renderer or proxy that cannot be built (unknown name, no mesh for the "mesh" proxy)."""


def make_renderers(sources: Scene, mesh, methods, k: int) -> dict:
    """The requested renderers over one proxy mesh, sharing its source depth maps."""
    depths = render_depth_maps(mesh, sources.cameras)
    makers = {
        "ulr": lambda: UlrRenderer(sources, mesh, config=UlrConfig(k=k), source_depths=depths),
        "ulr_pixel": lambda: UlrRenderer(sources, mesh, config=UlrConfig(k=k, blending="pixel"),
                                         source_depths=depths),
        "nearest": lambda: NearestViewRenderer(sources, mesh, source_depths=depths),
        "lightfield": lambda: LightFieldRenderer(sources, mesh),
        "lightfield_local": lambda: LightFieldRenderer(
            sources, mesh, config=LightFieldConfig(mode="local_depth"), source_depths=depths),
    }
    return {m: makers[m]() for m in methods}


def proxy_mesh(scene: Scene, kind: str):
    """The scene's proxy: "mesh" its own mesh, "photos" triangulated from its photos, "dense"
    with plane-sweep points too."""
    if kind == "mesh":
        if scene.mesh is None:
            raise RendererError(f"scene {scene.name!r} has no mesh; use --proxy photos")
        return scene.mesh
    if kind not in ("photos", "dense"):
        raise RendererError(f"unknown proxy {kind!r}; use photos, dense or mesh")
    return build_proxy(scene, ProxyConfig(dense=DenseConfig() if kind == "dense" else None)).mesh
