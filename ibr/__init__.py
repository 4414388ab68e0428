"""ibr: cameras, scenes and rendering — the base every other ibrnav package builds on."""

from ibr.camera import Camera, CameraError, intrinsics_from_fov, invert_rigid, rigid
from ibr.gl import GLContextError, create_context, shared_context

__all__ = ["Camera", "CameraError", "GLContextError", "create_context", "intrinsics_from_fov",
           "invert_rigid", "rigid", "shared_context"]
