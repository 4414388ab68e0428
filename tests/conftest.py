"""Shared fixtures: one headless GL context per test session (the one every renderer
shares), checked for GL errors after each test; the real-data folder when it exists."""

from __future__ import annotations

from pathlib import Path

import pytest

from ibr.gl import shared_context

REPO = Path(__file__).resolve().parents[1]
STRECHA = REPO.parent / "shared" / "data" / "strecha"


@pytest.fixture(scope="session")
def gl_ctx():
    return shared_context()


@pytest.fixture(autouse=True)
def _no_gl_errors():
    yield
    if shared_context.cache_info().currsize:  # only if some test made the context
        assert shared_context().error == "GL_NO_ERROR"


@pytest.fixture(scope="session")
def strecha_dir() -> Path:
    if not STRECHA.is_dir():
        pytest.skip(f"real data not found at {STRECHA}")
    return STRECHA


@pytest.fixture(scope="session")
def office():
    from ibr.synthetic import make_world

    return make_world("office", 0)
