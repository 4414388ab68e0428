"""ibr.render: the image-based renderers over a proxy mesh (unstructured lumigraph, the
plane-homography light field, nearest view), the factory that builds them by name, camera
paths for fly-throughs, and their leave-one-out evaluation."""

from ibr.render.camera_paths import fly_through, interpolate_cameras
from ibr.render.eval import EvalConfig, evaluate_scene, psnr, ssim
from ibr.render.lightfield import LightFieldConfig, LightFieldRenderer
from ibr.render.nearest_view import NearestViewRenderer
from ibr.render.renderers import METHODS, make_renderers, proxy_mesh
from ibr.render.ulr import UlrConfig, UlrRenderer

__all__ = ["METHODS", "EvalConfig", "LightFieldConfig", "LightFieldRenderer", "NearestViewRenderer", "UlrConfig",
           "UlrRenderer", "evaluate_scene", "fly_through", "interpolate_cameras", "make_renderers", "proxy_mesh",
           "psnr", "ssim"]
