"""The research notebooks: committed without outputs, and each runs top to bottom.

Every notebook reads ``OTJAX_NOTEBOOK_SIZE`` (``"full"`` by default); the
tests set ``"small"``, which keeps each notebook to a few hundred points and
well under a minute on a 2-core CPU. A failing cell fails the test with the
cell's traceback.
"""

import re
import time
from pathlib import Path

import nbformat
import pytest

import otjax

NOTEBOOKS = sorted((Path(__file__).resolve().parent.parent / "notebooks").glob("*.ipynb"))
EXPECTED = {"batched_collapse_scoring.ipynb", "gradient_relocation.ipynb", "reconstruction_gallery.ipynb"}
CELL_TIMEOUT_S = 300


def test_the_notebooks_are_there():
    assert EXPECTED <= {p.name for p in NOTEBOOKS}


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_committed_without_outputs(path):
    nb = nbformat.read(path, as_version=4)
    nbformat.validate(nb)
    dirty = [i for i, cell in enumerate(nb.cells)
             if cell.cell_type == "code" and (cell.get("outputs") or cell.get("execution_count") is not None)]
    assert not dirty, (f"{path.name}: cells {dirty} have outputs or execution counts; "
                       "strip them before committing")


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_uses_only_the_public_api(path):
    """otjax is imported as ``import otjax`` / ``from otjax import <public name>``, no ``._private``."""
    nb = nbformat.read(path, as_version=4)
    code = "\n".join(c.source for c in nb.cells if c.cell_type == "code")
    for line in code.splitlines():
        m = re.match(r"\s*from (otjax[\w.]*) import (.+)", line)
        if m:
            assert m.group(1) == "otjax", f"{path.name}: import from a submodule: {line.strip()}"
            names = [n.strip().split(" as ")[0] for n in m.group(2).split(",")]
            assert set(names) <= set(otjax.__all__), f"{path.name}: not public: {line.strip()}"
        m = re.match(r"\s*import (otjax[\w.]*)", line)
        if m:
            assert m.group(1) == "otjax", f"{path.name}: {line.strip()}"
    private = re.findall(r"\b(?:otjax|curves|datasets|metrics|stencil)\.(_\w+)", code)
    assert not private, f"{path.name}: private names used: {private}"
    assert not re.findall(r"\.(_[a-z]\w*)", code), f"{path.name}: private attribute access"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.stem)
def test_runs_top_to_bottom(path, monkeypatch):
    from nbclient import NotebookClient

    # The kernel inherits this process's environment.
    monkeypatch.setenv("OTJAX_NOTEBOOK_SIZE", "small")
    monkeypatch.setenv("JAX_PLATFORMS", "cpu")
    nb = nbformat.read(path, as_version=4)
    client = NotebookClient(nb, timeout=CELL_TIMEOUT_S, kernel_name="python3",
                            resources={"metadata": {"path": str(path.parent)}})
    t0 = time.perf_counter()
    client.execute()  # raises CellExecutionError on the first failing cell
    seconds = time.perf_counter() - t0
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])
              if o.get("output_type") == "error"]
    assert not errors
    print(f"{path.name}: {seconds:.1f} s")
