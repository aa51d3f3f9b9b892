"""The bifurcation-diagram notebook runs top to bottom (see test_notebooks.py; a file of its own so
that the xdist workers, which take whole files, share the notebooks' time)."""
import pytest

from test_notebooks import NOTEBOOKS, checks_that_ran, run_notebook

# The validation tier (-m validation): a notebook run top to bottom.
pytestmark = pytest.mark.validation


def test_bifurcation_diagram_notebook_runs_and_checks_its_results(tmp_path, monkeypatch):
    (path,) = [p for p in NOTEBOOKS if p.name == "bifurcation_diagram.ipynb"]
    assert checks_that_ran(run_notebook(path, tmp_path, monkeypatch)) >= 1
