import moderngl
import pytest

from ibr import gl


def test_missing_egl_gives_the_fix(monkeypatch):
    def no_egl(**kwargs):
        raise Exception("libEGL.so: cannot open shared object file")

    monkeypatch.setattr(moderngl, "create_context", no_egl)
    with pytest.raises(gl.GLContextError, match="apt-get install libegl1 libgl1-mesa-dri") as e:
        gl.create_context()
    assert "libEGL.so: cannot open" in str(e.value)


def test_context_is_headless_gl_45(gl_ctx):
    assert gl_ctx.version_code >= 430
