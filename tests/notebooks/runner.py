"""Runs one research notebook top to bottom at its small size.

Every notebook reads ``OTJAX_NOTEBOOK_SIZE`` (``"full"`` by default); the
tests set ``"small"``, which keeps each notebook to a few hundred or a few
thousand points on a 2-core CPU. Each notebook has its own test file in this
folder, so that the suite's workers (``--dist loadfile``) run them side by
side; ``tests/test_notebooks.py`` checks that every notebook has one.
"""

import time
from pathlib import Path

import nbformat

NOTEBOOK_DIR = Path(__file__).resolve().parent.parent.parent / "notebooks"
CELL_TIMEOUT_S = 300


def run_notebook(name: str, monkeypatch) -> float:
    """Executes ``notebooks/<name>`` in a fresh kernel; a failing cell raises
    with its traceback. Returns the wall time in seconds."""
    from nbclient import NotebookClient

    # The kernel inherits this process's environment.
    monkeypatch.setenv("OTJAX_NOTEBOOK_SIZE", "small")
    monkeypatch.setenv("JAX_PLATFORMS", "cpu")
    path = NOTEBOOK_DIR / name
    nb = nbformat.read(path, as_version=4)
    client = NotebookClient(nb, timeout=CELL_TIMEOUT_S, kernel_name="python3",
                            resources={"metadata": {"path": str(path.parent)}})
    t0 = time.perf_counter()
    client.execute()  # raises CellExecutionError on the first failing cell
    seconds = time.perf_counter() - t0
    errors = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])
              if o.get("output_type") == "error"]
    assert not errors, f"{name}: {errors[0].get('ename')}: {errors[0].get('evalue')}"
    print(f"{name}: {seconds:.1f} s")  # shown with -s; the suite's slowest files
    return seconds
