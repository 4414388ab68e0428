"""Shared fixtures: one headless GL context per test session (the one every renderer
shares), checked for GL errors after each test; the real-data folder when it exists; an
`ibrnav` command run in-process."""

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


@pytest.fixture(scope="session")
def ibrnav_command():
    """Run one `ibrnav` command in-process as a user types it (`ibrnav_command("render", ...)`);
    returns its exit code. An `InputError` is raised, not turned into the console script's
    one-line message, so tests can match it."""
    from ibrnav.cli import build_parser

    def run(*argv) -> int:
        args = build_parser().parse_args([str(a) for a in argv])
        return args.func(args)
    return run
