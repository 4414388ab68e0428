"""The GL context factory: headless OpenGL through EGL with moderngl.

Every renderer receives its context from here. On CI and laptops without a GPU this is
Mesa's llvmpipe (CPU); on a machine with an NVIDIA driver the same code runs on the GPU.
"""

from __future__ import annotations

import functools
from importlib import resources

import moderngl

GL_CLIP_DISTANCE0 = 0x3000

EGL_FIX = (
    "ibrnav renders headless through EGL and could not create an OpenGL context.\n"
    "Fix: install the EGL and Mesa libraries, e.g. on Debian/Ubuntu\n"
    "    sudo apt-get install libegl1 libgl1-mesa-dri libgles2\n"
    "(or your GPU driver's EGL), then run again. On a machine with a display you may also\n"
    "set IBRNAV_GL_BACKEND=default to let moderngl pick its own backend."
)


class GLContextError(RuntimeError):
    """No OpenGL context could be created; the message says how to fix it."""


def create_context(require: int = 430) -> moderngl.Context:
    """A new standalone moderngl context (EGL by default, IBRNAV_GL_BACKEND to override).
    `require` 430: the shaders are GLSL 4.30 and the reductions are compute shaders (a
    driver asked for less may hand out a 3.3 core context without them, as NVIDIA's does)."""
    import os

    backend = os.environ.get("IBRNAV_GL_BACKEND", "egl")
    kwargs = {} if backend == "default" else {"backend": backend}
    try:
        return moderngl.create_context(standalone=True, require=require, **kwargs)
    except Exception as e:  # moderngl/glcontext raise bare Exceptions for a missing libEGL
        raise GLContextError(f"{EGL_FIX}\n(underlying error: {e})") from e


@functools.cache
def shared_context() -> moderngl.Context:
    """One context per process, shared by every renderer that is not given one."""
    return create_context()


def shader_source(name: str, package: str = "ibr") -> str:
    """Text of `<package>/shaders/<name>.glsl` (package data)."""
    return (resources.files(package) / "shaders" / f"{name}.glsl").read_text()


def _header(defines: dict | None) -> str:
    return "#version 430 core\n" + "".join(f"#define {k} {v}\n" for k, v in (defines or {}).items())


def load_program(ctx: moderngl.Context, name: str, defines: dict | None = None,
                 varyings: tuple[str, ...] = (), package: str = "ibr") -> moderngl.Program:
    """Compile `<package>/shaders/<name>.glsl`, whose stages are selected with
    `#if defined VERTEX_SHADER` / `FRAGMENT_SHADER` / `GEOMETRY_SHADER` (moderngl-window style)."""
    source = shader_source(name, package)
    head = _header(defines)

    def stage(define):
        return head + f"#define {define} 1\n" + source if f"defined {define}" in source else None

    return ctx.program(
        vertex_shader=stage("VERTEX_SHADER"),
        fragment_shader=stage("FRAGMENT_SHADER"),
        geometry_shader=stage("GEOMETRY_SHADER"),
        varyings=varyings,
    )


def load_compute(ctx: moderngl.Context, name: str, defines: dict | None = None,
                 package: str = "ibr") -> moderngl.ComputeShader:
    """Compile the `#if defined COMPUTE_SHADER` stage of `<package>/shaders/<name>.glsl`."""
    return ctx.compute_shader(_header(defines) + "#define COMPUTE_SHADER 1\n" + shader_source(name, package))
