"""notebooks/surface_reconstruction.ipynb runs top to bottom at its small size; its last cell
checks the batched scores against HiGHS, the snapshots' vertex counts and mass, and the filter."""

from tests.notebooks.runner import run_notebook


def test_runs_top_to_bottom(monkeypatch):
    run_notebook("surface_reconstruction.ipynb", monkeypatch)
