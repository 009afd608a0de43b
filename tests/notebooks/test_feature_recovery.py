"""notebooks/feature_recovery.ipynb runs top to bottom at its small size."""

from tests.notebooks.runner import run_notebook


def test_runs_top_to_bottom(monkeypatch):
    run_notebook("feature_recovery.ipynb", monkeypatch)
