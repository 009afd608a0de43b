"""The research notebooks: committed without outputs, public API only, and each
run top to bottom by its own file in ``tests/notebooks/``."""

import re
from pathlib import Path

import nbformat
import pytest

import otjax

NOTEBOOKS = sorted((Path(__file__).resolve().parent.parent / "notebooks").glob("*.ipynb"))
EXPECTED = {"batched_collapse_scoring.ipynb", "feature_recovery.ipynb", "gradient_relocation.ipynb",
            "reconstruction_gallery.ipynb", "surface_reconstruction.ipynb"}


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
def test_each_notebook_is_run_by_its_own_test_file(path):
    runner = Path(__file__).resolve().parent / "notebooks" / f"test_{path.stem}.py"
    assert runner.is_file(), f"{path.name}: add {runner.relative_to(runner.parents[2])} (see tests/notebooks/runner.py)"
    assert f'run_notebook("{path.name}"' in runner.read_text(encoding="utf-8")
