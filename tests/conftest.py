import os

for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

import tempfile  # noqa: E402

# One persistent XLA cache for the test session, inherited by the CLI and notebook subprocesses,
# so code compiled by one process is not compiled again by the next.
os.environ.setdefault("JAX_COMPILATION_CACHE_DIR", tempfile.mkdtemp(prefix="jaxrod-xla-"))
# Cache every compilation, not only those over 1 s: the notebook and CLI subprocesses then
# recompile nothing that a test compiled before them.
os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "0")
# The CLI's exported programs (jaxrod.aot) are lowered inside a wrapper: their compiled code is not
# the library tests' code, so CLI runs in the suite would compile it all again. Off here; the
# mechanism itself is tested in test_aot.py.
os.environ.setdefault("JAXROD_PROGRAMS", "0")

# Most of the suite's time is XLA compiling several hundred distinct programs, most of which then
# run for milliseconds. These flags change how the machine code is generated and scheduled, not the
# arithmetic (XLA's fast-math is off, so floating-point operations are neither reassociated nor
# contracted; at most a reduction's summation order differs, at roundoff):
# - LLVM's backend optimisation level 0: measured on the whole suite, 617 s of test time against 700 s;
# - the classic elemental emitters instead of XLA:CPU's MLIR fusion emitters, and the default
#   instead of the concurrency-optimised scheduler: XLA compile time of test_trefoil_twist.py and
#   test_solvers.py, run side by side, 27 s against 53 s (wall 55 s against 79 s).
# Appended, so flags a developer sets stay; inherited by the CLI and notebook subprocesses, which
# then share the compile cache with the tests.
_flags = os.environ.get("XLA_FLAGS", "").split()
for _flag in ("--xla_backend_optimization_level=0", "--xla_llvm_disable_expensive_passes=true",
              "--xla_cpu_use_fusion_emitters=false", "--xla_cpu_enable_concurrency_optimized_scheduler=false"):
    if _flag not in _flags:  # the xdist workers inherit the controller's flags: add each once
        _flags.append(_flag)
os.environ["XLA_FLAGS"] = " ".join(_flags)

import jaxrod  # noqa: E402,F401  (float64 before any test builds arrays)


# Longest files first, measured with --durations=0 (busy seconds per file on 2 cores), so that the
# two xdist workers, which take whole files in collection order (``--no-loadscope-reorder`` in
# pyproject.toml: by default xdist reorders files by their number of tests, which ignores this
# list), finish together: first the files of the smoke and validation tiers (deselected in the fast
# tier), then those of the fast tier. Files not listed (short ones, new ones) come after,
# alphabetically.
_LONGEST_FIRST = ("test_benchmarks_smoke_b.py", "test_benchmarks_smoke_a.py", "test_notebooks.py",
                  "test_differentiable.py", "test_atlas.py", "test_bifurcation_knots.py", "test_atlas_kinds.py",
                  "test_branch_check.py", "test_newcomer.py", "test_critical_curve_checks.py", "test_resume.py",
                  "test_notebook_damped_dynamics.py", "test_notebook_bifurcation_diagram.py",
                  "test_located_once.py", "test_interrupt_and_lock.py",
                  "test_shear.py", "test_sparse_stability.py", "test_cli.py", "test_symmetry.py",
                  "test_bifurcation_rods.py", "test_endloads.py",
                  "test_conventions.py", "test_convergence.py", "test_solvers.py", "test_extending.py",
                  "test_trefoil_twist.py", "test_energy.py", "test_backends.py", "test_hessian.py",
                  "test_critical_error.py", "test_helix_checks.py", "test_event_curve.py", "test_topology.py",
                  "test_dynamics.py", "test_sparse_contact.py", "test_contact.py", "test_stability.py",
                  "test_knots.py", "test_analysis.py", "test_readme.py", "test_bifurcation_analytic.py",
                  "test_michell.py", "test_docs_blocks.py", "test_traceable.py", "test_michell_contact.py",
                  "test_compile_ahead.py", "test_properties.py", "test_aot.py", "test_banded.py",
                  "test_structure.py", "test_clamped_linking.py", "test_programs_shared.py", "test_lk0.py",
                  "test_analyze_study_files.py", "test_plotting.py", "test_open_knot.py")


def pytest_collection_modifyitems(session, config, items):
    rank = {name: i for i, name in enumerate(_LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: order within a file kept
