"""The benchmark scripts in their small mode (``_bench.SMOKE``), as the smoke test runs them.

``SCRIPTS``: each script with the arguments it is run with and the files it must write; ``group``
spreads them over the test files (``tests/test_benchmarks_smoke_a.py``, ``_b.py``; split by the times
measured one script at a time with the suite's XLA flags) so that the
suite's workers share them about evenly by time. ``NO_SMOKE``: scripts that have no small mode,
with the reason. ``run`` runs one script in a subprocess, its results in a folder of its own.
"""
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
    "batch.py": _entry("a", ["batch.md"], ["2"]),
    "bifurcation_michell.py": _entry("a", ["bifurcation_michell.csv", "bifurcation_michell.md",
                                           "bifurcation_michell.png"]),
    "bifurcation_trefoil.py": _entry("a", ["bifurcation_trefoil.csv", "bifurcation_trefoil.json",
                                           "bifurcation_trefoil.md", "bifurcation_trefoil.png"]),
    "critical_curve_vs_study.py": _entry("b", ["critical_curve_vs_study.json", "critical_curve_vs_study.md"]),
    "cli_start.py": _entry("a", ["cli_start.md", "cli_start.json"]),
    "cli_startup_breakdown.py": _entry("b", ["cli_startup_breakdown.md"]),
    "command1.py": _entry("b", ["command1.md", "command1.json"]),
    "command1_diagram.py": _entry("b", ["command1_diagram.md", "command1_diagram.json"]),
    "diagram_steps.py": _entry("b", ["diagram_steps.md", "diagram_steps.json"]),
    "dynamics.py": _entry("a", ["dynamics.csv", "dynamics.md", "dynamics.png"]),
    "dynamics_accuracy.py": _entry("a", ["dynamics_accuracy.csv", "dynamics_accuracy.md", "dynamics_accuracy.png"]),
    "dynamics_shape.py": _entry("a", ["dynamics_shape.csv", "dynamics_shape.md", "dynamics_shape.npz"]),
    "fold_curve_nu.py": _entry("b", ["fold_curve_nu.json", "fold_curve_nu.csv", "fold_curve_nu.md",
                                     "fold_curve_nu.png"]),
    "fold_curve_ratio.py": _entry("a", ["fold_curve_ratio.json", "fold_curve_ratio.csv", "fold_curve_ratio.md",
                                        "fold_curve_ratio.png"]),
    "fold_curve_wells.py": _entry("b", ["fold_curve_wells_plus.json", "fold_curve_wells.md"]),
    "fold_sensitivity.py": _entry("b", ["fold_sensitivity.json", "fold_sensitivity.md"]),
    "helical_buckling.py": _entry("b", ["helical_buckling.json", "helical_buckling.png"]),
    "helix_reference.py": _entry("a", ["helix_reference.json"]),
    "hysteresis_trefoil.py": _entry("a", ["hysteresis_trefoil.csv", "hysteresis_trefoil.json",
                                          "hysteresis_trefoil.md", "hysteresis_trefoil.png"]),
    "michell.py": _entry("b", ["michell.md", "michell.png"]),
    "onset_fine_step.py": _entry("a", ["onset_fine_step.md"]),
    "open_knot.py": _entry("b", ["open_knot.csv", "open_knot.json"]),
    "plectoneme.py": _entry("b", ["plectoneme.csv", "plectoneme.json", "plectoneme.png"]),
    "redesign_same_answers.py": _entry("b", ["redesign_same_answers.md", "redesign_same_answers.json"]),
    "restabilise_trefoil.py": _entry("a", ["restabilise_trefoil.json", "restabilise_trefoil.md"]),
    "sparse_fold.py": _entry("b", ["sparse_fold.json", "sparse_fold.md"]),
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
    env = dict(os.environ, JAXROD_SMOKE="1", JAXROD_BENCH_OUT=str(out), OPENBLAS_NUM_THREADS="1",
               MPLBACKEND="Agg")
    t = time.perf_counter()
    proc = subprocess.run([sys.executable, os.path.join(HERE, script), *entry["args"]], cwd=HERE, env=env,
                          capture_output=True, text=True, timeout=timeout)
    return proc.returncode, time.perf_counter() - t, proc.stdout + proc.stderr


def missing_outputs(script, out):
    """The files ``script`` should have written to ``out`` but did not."""
    return [name for name in SCRIPTS[script]["outputs"] if not os.path.exists(os.path.join(out, name))]
