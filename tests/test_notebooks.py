"""Every notebook under notebooks/ executes top to bottom, so none can rot. A notebook that
needs the real photos says so in its metadata (`"ibrnav": {"needs_real_data": true}`) and is
skipped, with the reason, by the same fixture as the real-data tests when `../shared/data` is
absent; the others fall back to synthetic scenes and run anywhere. The committed notebooks
are executed (with their figures, for reading on GitHub) and small."""

from pathlib import Path

import nbformat
import pytest
from nbclient import NotebookClient

NOTEBOOKS = sorted((Path(__file__).resolve().parents[1] / "notebooks").glob("*.ipynb"))
MAX_BYTES = 1_000_000


def needs_real_data(nb) -> bool:
    return bool(nb.metadata.get("ibrnav", {}).get("needs_real_data", False))


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_runs(path, request):
    nb = nbformat.read(path, as_version=4)
    if needs_real_data(nb):
        request.getfixturevalue("strecha_dir")  # skips, naming the missing folder, without ../shared
    NotebookClient(nb, timeout=600, kernel_name="python3",
                   resources={"metadata": {"path": str(path.parent)}}).execute()
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])
              if o.output_type == "error"]
    assert not errors


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_committed_notebook_is_small_and_states_what_it_needs(path):
    assert path.stat().st_size < MAX_BYTES, f"{path.name}: {path.stat().st_size} bytes (lower the figure dpi)"
    nb = nbformat.read(path, as_version=4)
    code = "".join(c.source for c in nb.cells if c.cell_type == "code")
    if "shared" in code and not needs_real_data(nb):
        assert "is_dir()" in code, f"{path.name} reads ../shared without a fallback or needs_real_data"
