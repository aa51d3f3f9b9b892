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

import jaxrod  # noqa: E402,F401  (float64 before any test builds arrays)
