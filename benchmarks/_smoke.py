"""The benchmark scripts in their small mode (``_bench.SMOKE``), as the smoke test runs them.

``SCRIPTS``: each script with the arguments it is run with and the files it must write; ``group``
spreads them over the test files (``tests/test_benchmarks_smoke_a.py``, ``_b.py``) by family, so that
the scripts of one process share their compiled programs (a program is compiled per node count: the
trefoil at N = 61 and the command line's tiny study in group a; the trefoil at N = 41, Michell's
ring and the end-loaded rods in group b), and so that the suite's workers share them about evenly by
time. ``NO_SMOKE``: scripts that have no small mode,
with the reason. ``OWN_PROCESS``: scripts that must run in a process of their own, with the reason.

``run`` runs one script in a subprocess, its results in a folder of its own. ``run_many`` runs
several scripts one after another in one subprocess (``runpy``, as ``__main__``): Python, JAX and
jaxrod are imported once and a program one script compiled is not compiled again by the next, which
is most of a small run's time.
"""
import json
import os
import subprocess
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))


def _entry(group, outputs, args=()):
    return {"group": group, "outputs": tuple(outputs), "args": tuple(args)}


SCRIPTS = {
    "accuracy_trefoil.py": _entry("b", ["accuracy_trefoil.json", "accuracy_trefoil.png"]),
    "atlas_parallel.py": _entry("b", ["atlas_parallel.md"], ["1"]),
    "batch.py": _entry("b", ["batch.md"], ["2"]),
    "bifurcation_michell.py": _entry("b", ["bifurcation_michell.csv", "bifurcation_michell.json",
                                           "bifurcation_michell.md", "bifurcation_michell.png"]),
    "bifurcation_trefoil.py": _entry("a", ["bifurcation_trefoil.csv", "bifurcation_trefoil.json",
                                           "bifurcation_trefoil.md", "bifurcation_trefoil.png"]),
    "critical_curve_vs_study.py": _entry("b", ["critical_curve_vs_study.json", "critical_curve_vs_study.md"]),
    "cli_start.py": _entry("a", ["cli_start.md", "cli_start.json"]),
    "cli_startup_breakdown.py": _entry("a", ["cli_startup_breakdown.md", "cli_startup_breakdown.json"]),
    "command1.py": _entry("a", ["command1.md", "command1.json"]),
    "command1_diagram.py": _entry("a", ["command1_diagram.md", "command1_diagram.json"]),
    "diagram_steps.py": _entry("a", ["diagram_steps.md", "diagram_steps.json"]),
    "differentiable_trefoil.py": _entry("a", ["differentiable_trefoil.json", "differentiable_trefoil.md"]),
    "dynamics.py": _entry("b", ["dynamics.csv", "dynamics.md", "dynamics.png"]),
    "dynamics_accuracy.py": _entry("b", ["dynamics_accuracy.csv", "dynamics_accuracy.md", "dynamics_accuracy.png"]),
    "dynamics_shape.py": _entry("a", ["dynamics_shape.csv", "dynamics_shape.md", "dynamics_shape.npz"]),
    "figure_eight_accuracy.py": _entry("b", ["figure_eight_accuracy.json", "figure_eight_accuracy.md",
                                             "figure_eight_accuracy.png"]),
    "fold_curve_nu.py": _entry("a", ["fold_curve_nu.json", "fold_curve_nu.csv", "fold_curve_nu.md",
                                     "fold_curve_nu.png"]),
    "fold_curve_ratio.py": _entry("a", ["fold_curve_ratio.json", "fold_curve_ratio.csv", "fold_curve_ratio.md",
                                        "fold_curve_ratio.png"]),
    "fold_curve_wells.py": _entry("a", ["fold_curve_wells_plus.json", "fold_curve_wells.md"]),
    "fold_sensitivity.py": _entry("a", ["fold_sensitivity.json", "fold_sensitivity.md"]),
    "helical_buckling.py": _entry("b", ["helical_buckling.json", "helical_buckling.png"]),
    "helix_reference.py": _entry("b", ["helix_reference.json"]),
    "hysteresis_trefoil.py": _entry("a", ["hysteresis_trefoil.csv", "hysteresis_trefoil.json",
                                          "hysteresis_trefoil.md", "hysteresis_trefoil.png"]),
    "large_n_sides.py": _entry("a", ["large_n_sides.json", "large_n_sides.md"]),
    "loose_limit.py": _entry("b", ["loose_limit.json", "loose_limit.md", "loose_limit.png"]),
    "michell.py": _entry("b", ["michell.md", "michell.png"]),
    "onset_fine_step.py": _entry("b", ["onset_fine_step.md"]),
    "open_knot.py": _entry("b", ["open_knot.csv", "open_knot.json"]),
    "per_step.py": _entry("b", ["per_step.json", "per_step.md"]),
    "plectoneme.py": _entry("b", ["plectoneme.csv", "plectoneme.json", "plectoneme.png"]),
    "redesign_same_answers.py": _entry("a", ["redesign_same_answers.md", "redesign_same_answers.json"]),
    "restabilise_trefoil.py": _entry("a", ["restabilise_trefoil.json", "restabilise_trefoil.md"]),
    "shear_trefoil.py": _entry("a", ["shear_trefoil.json", "shear_trefoil.md", "shear_trefoil_limit.png"]),
    "shear_kirchhoff_limit.py": _entry("b", ["shear_kirchhoff_limit.json", "shear_kirchhoff_limit.md",
                                             "shear_kirchhoff_limit.png"]),
    "sparse_fold.py": _entry("a", ["sparse_fold.json", "sparse_fold.md"]),
    "sparse_contact.py": _entry("a", ["sparse_contact.csv", "sparse_contact.md", "sparse_contact.png",
                                     "sparse_contact_accuracy.png"]),
    "sparse_tightening_end.py": _entry("a", ["sparse_tightening_end.json", "sparse_tightening_end.md"]),
    "speed.py": _entry("a", ["speed.csv", "BENCHMARKS.md", "speed.png"]),
    "tension_twist.py": _entry("b", ["tension_twist.json", "tension_twist.png"]),
    "trefoil.py": _entry("a", ["trefoil_critical.csv", "trefoil_critical.md"]),
    "trefoil_n120.py": _entry("a", ["trefoil_n120.json", "trefoil_n120.md"]),
}

# Scripts with no small mode, and why (the smoke test prints these).
NO_SMOKE = {
    "peer_pyelastica.py": "needs PyElastica (pip install pyelastica), a benchmark-only package that the "
                          "test environment does not install",
}


def all_scripts():
    """Every script in benchmarks/ (helpers, whose names start with '_', left out)."""
    return sorted(f for f in os.listdir(HERE) if f.endswith(".py") and not f.startswith("_"))


def run(script, out, timeout=600):
    """Run ``script`` in its small mode with its results in ``out``. -> (returncode, seconds, output)."""
    entry = SCRIPTS[script]
    t = time.perf_counter()
    proc = subprocess.run([sys.executable, os.path.join(HERE, script), *entry["args"]], cwd=HERE, env=_env(out),
                          capture_output=True, text=True, timeout=timeout)
    return proc.returncode, time.perf_counter() - t, proc.stdout + proc.stderr


def missing_outputs(script, out):
    """The files ``script`` should have written to ``out`` but did not."""
    return [name for name in SCRIPTS[script]["outputs"] if not os.path.exists(os.path.join(out, name))]

# Scripts run in a process of their own, not in ``run_many``'s shared one, and why.
OWN_PROCESS = {
    "speed.py": "switches off JAX's compilation cache (jax.config) for its timings, which would carry over "
                "to the scripts after it",
}

_MARK = "@@smoke-result@@ "


def _env(out):
    return dict(os.environ, JAXROD_SMOKE="1", JAXROD_BENCH_OUT=str(out), OPENBLAS_NUM_THREADS="1",
                MPLBACKEND="Agg")


def run_many(scripts, out_root, timeout=900):
    """Run ``scripts`` in their small mode one after another in one subprocess, each with its results
    in ``out_root/<script stem>``. -> {script: (returncode, seconds, output)}; a script the process
    never reached (it crashed or timed out) has returncode None and the process's output."""
    outs = {script: os.path.join(str(out_root), script[:-3]) for script in scripts}
    cmd = [sys.executable, os.path.abspath(__file__), "--run-many", json.dumps(outs)]
    try:
        proc = subprocess.run(cmd, cwd=HERE, env=_env(out_root), capture_output=True, text=True, timeout=timeout)
        text = proc.stdout + proc.stderr
    except subprocess.TimeoutExpired as exc:
        text = f"timed out after {timeout} s\n{exc.stdout or ''}{exc.stderr or ''}"
    results = {}
    for line in text.splitlines():
        if line.startswith(_MARK):
            r = json.loads(line[len(_MARK):])
            results[r["script"]] = (r["returncode"], r["seconds"], r["output"])
    return {s: results.get(s, (None, 0.0, text[-6000:])) for s in scripts}


def _exit_code(exc):
    code = exc.code
    return 0 if code is None else code if isinstance(code, int) else 1


def _run_here(script, out):
    """Run ``script`` as ``__main__`` in this process, its results in ``out``. -> (returncode, output)."""
    import contextlib
    import io
    import runpy
    import traceback

    import _bench
    import matplotlib
    import matplotlib.pyplot as plt

    os.makedirs(out, exist_ok=True)
    os.environ["JAXROD_BENCH_OUT"] = out
    _bench.results_dir.cache_clear()
    path = os.path.join(HERE, script)
    argv, cwd, sys_path = sys.argv[:], os.getcwd(), sys.path[:]
    sys.argv = [path, *SCRIPTS[script]["args"]]
    buf, code = io.StringIO(), 0
    try:
        with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(buf):
            runpy.run_path(path, run_name="__main__")
    except SystemExit as exc:
        code = _exit_code(exc)
        if code:
            buf.write(f"\nSystemExit: {exc.code}\n")
    except BaseException:  # noqa: BLE001  (any failure of the script is reported under its name)
        buf.write(traceback.format_exc())
        code = 1
    finally:
        sys.argv, sys.path[:] = argv, sys_path
        os.chdir(cwd)
        plt.close("all")
        matplotlib.rcdefaults()
    return code, buf.getvalue()


def _main_run_many(outs):
    sys.path.insert(0, HERE)
    for script, out in outs.items():
        t = time.perf_counter()
        code, output = _run_here(script, out)
        result = dict(script=script, returncode=code, seconds=time.perf_counter() - t, output=output[-6000:])
        print(_MARK + json.dumps(result), flush=True)


if __name__ == "__main__" and sys.argv[1:2] == ["--run-many"]:
    _main_run_many(json.loads(sys.argv[2]))
