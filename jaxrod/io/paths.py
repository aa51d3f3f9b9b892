"""Where this repository's committed benchmark results are, from wherever a notebook runs.

The notebooks plot results that the benchmarks wrote into ``benchmarks/results/``. A path
relative to the working directory ("../benchmarks/results") holds only when the kernel runs in
``notebooks/``; ``benchmark_results`` looks instead from the notebook's own folder (Jupyter tells
the kernel which notebook it runs: ``JPY_SESSION_NAME``; VS Code: ``__vsc_ipynb_file__``), from
the working directory and every folder above it, and from the source tree that ``jaxrod`` was
imported from (an editable install or a checkout on ``sys.path``).
"""
from __future__ import annotations

import os
import pathlib

__all__ = ["benchmark_results"]

RESULTS = ("benchmarks", "results")


def _starts(notebook=None):
    """Folders to search from, in order (each with its parents)."""
    import jaxrod

    first = []
    for path in (notebook, os.environ.get("JPY_SESSION_NAME"), _vscode_notebook()):
        if path:
            first.append(pathlib.Path(path).expanduser().resolve().parent)
    return first + [pathlib.Path.cwd(), pathlib.Path(jaxrod.__file__).resolve().parent]


def _vscode_notebook():
    try:  # VS Code's Jupyter kernels define the notebook's path in the user namespace
        from IPython import get_ipython

        shell = get_ipython()
        return None if shell is None else shell.user_ns.get("__vsc_ipynb_file__")
    except ImportError:
        return None


def benchmark_results(*parts, notebook=None):
    """The path of ``benchmarks/results/<parts...>`` in this repository (a ``pathlib.Path``), found
    from the notebook's folder (``notebook=`` or what Jupyter tells the kernel), the working
    directory or jaxrod's source tree, each with the folders above it. Raises FileNotFoundError
    saying where it looked when none of them is inside the repository (jaxrod installed from a
    wheel, the notebook copied elsewhere)."""
    looked = []
    for start in _starts(notebook):
        for base in (start, *start.parents):
            candidate = base.joinpath(*RESULTS, *parts)
            if candidate.exists():
                return candidate
        looked.append(str(start))
    raise FileNotFoundError(
        f"{'/'.join(RESULTS + parts)} not found in or above {', '.join(dict.fromkeys(looked))}: the notebooks read "
        "the results committed in the jaxrod repository; open them from inside a clone of it")
