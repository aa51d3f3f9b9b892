"""Notebooks run top to bottom, from a working directory outside the repository (issue 16,
defect 10: trefoil_twist.ipynb read '../benchmarks/results/...' and failed anywhere but in
notebooks/). The kernel is told which notebook it runs, as Jupyter tells it (JPY_SESSION_NAME)."""
import pathlib
import re

import pytest

from jaxrod.io.paths import benchmark_results

REPO = pathlib.Path(__file__).resolve().parent.parent
NOTEBOOKS = sorted((REPO / "notebooks").glob("*.ipynb"))
# The two longest notebooks run from files of their own (test_notebook_damped_dynamics.py,
# test_notebook_bifurcation_diagram.py), so that the two xdist workers, which take whole files,
# share the notebooks' minutes between them.
ELSEWHERE = ("damped_dynamics.ipynb", "bifurcation_diagram.ipynb")


def run_notebook(path, tmp_path, monkeypatch):
    # imported here, not at collection: nbformat's schema validation imports jsonschema's format
    # checkers (seconds), which every xdist worker would pay while collecting
    import nbformat
    from nbclient import NotebookClient

    monkeypatch.setenv("JPY_SESSION_NAME", str(path))
    nb = nbformat.read(path, as_version=4)
    NotebookClient(nb, timeout=900, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}).execute()
    return nb


def checks_that_ran(nb):
    """The number of ``assert`` statements in the notebook's code cells, after checking that every
    code cell ran (a cell that raises, an assert included, stops the run with CellExecutionError)."""
    code = [cell for cell in nb.cells if cell.cell_type == "code"]
    assert all(cell.execution_count is not None for cell in code)
    return sum(len(re.findall(r"^\s*assert ", cell.source, flags=re.M)) for cell in code)


def test_there_are_notebooks_and_each_is_run():
    assert NOTEBOOKS and all((REPO / "notebooks" / name).exists() for name in ELSEWHERE)


@pytest.mark.validation  # the validation tier (-m validation): notebooks run top to bottom
@pytest.mark.parametrize("path", [p for p in NOTEBOOKS if p.name not in ELSEWHERE], ids=lambda p: p.name)
def test_notebook_runs_and_checks_its_results(path, tmp_path, monkeypatch):
    assert checks_that_ran(run_notebook(path, tmp_path, monkeypatch)) >= 1


def test_benchmark_results_are_found_from_the_notebook_or_the_working_directory(tmp_path, monkeypatch):
    target = REPO / "benchmarks" / "results" / "trefoil_critical.csv"
    monkeypatch.delenv("JPY_SESSION_NAME", raising=False)
    monkeypatch.chdir(REPO / "docs")  # a folder inside the repository: found above it
    assert benchmark_results("trefoil_critical.csv") == target
    monkeypatch.chdir(tmp_path)  # outside: from the notebook's own folder
    assert benchmark_results("trefoil_critical.csv", notebook=REPO / "notebooks" / "x.ipynb") == target
    monkeypatch.setenv("JPY_SESSION_NAME", str(REPO / "notebooks" / "trefoil_twist.ipynb"))
    assert benchmark_results("trefoil_critical.csv") == target
    with pytest.raises(FileNotFoundError, match="benchmarks/results/no_such.csv not found in or above"):
        benchmark_results("no_such.csv")
