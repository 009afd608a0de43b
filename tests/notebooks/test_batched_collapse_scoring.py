"""notebooks/batched_collapse_scoring.ipynb runs top to bottom at its small size."""

from tests.notebooks.runner import run_notebook


def test_runs_top_to_bottom(monkeypatch):
    run_notebook("batched_collapse_scoring.ipynb", monkeypatch)
