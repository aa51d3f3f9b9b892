"""The damped-dynamics notebook runs top to bottom (see test_notebooks.py; a file of its own so
that the xdist workers share the notebooks' time)."""
import pytest

from test_notebooks import NOTEBOOKS, checks_that_ran, run_notebook

# The validation tier (-m validation): a notebook run top to bottom.
pytestmark = pytest.mark.validation


def test_damped_dynamics_notebook_runs_and_checks_its_results(tmp_path, monkeypatch):
    (path,) = [p for p in NOTEBOOKS if p.name == "damped_dynamics.ipynb"]
    assert checks_that_ran(run_notebook(path, tmp_path, monkeypatch)) >= 1
