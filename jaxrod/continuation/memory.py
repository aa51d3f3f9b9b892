"""Memory of the dense path: what a scene's n x n Hessian needs (``dense_memory_bytes``), what the
machine has left (``available_memory_bytes``), and the refusal of a scene that does not fit, before
anything is compiled (``check_dense_memory``)."""
from __future__ import annotations

import math


# Memory of the dense path, in bytes: DENSE_HESSIAN_COPIES * 8 n^2 + DENSE_BYTES_PER_DOF * n for n
# DOFs, fitted to the largest buffer, the compiled damped-Newton loop of ``relax`` (the Hessian and
# its copies, allocated by XLA in one piece).
DENSE_HESSIAN_COPIES = 6.4
DENSE_BYTES_PER_DOF = 8 * 256
# The interpreter, the JAX/XLA runtime and the compiled code, besides the arrays.
PROCESS_BASE_BYTES = 1.0e9


def dense_memory_bytes(n_dof):
    """Bytes the dense linear algebra of a scene of ``n_dof`` DOFs needs at its peak (the
    damped-Newton corrector's n x n buffers; see DENSE_HESSIAN_COPIES)."""
    n = float(n_dof)
    return 8.0 * DENSE_HESSIAN_COPIES * n * n + DENSE_BYTES_PER_DOF * n


def available_memory_bytes():
    """Memory this process may still use, in bytes: MemAvailable of /proc/meminfo (Linux), else
    the physical memory (os.sysconf); a cgroup (container) limit, where lower, wins. None if
    unknown."""
    import os

    found = None
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    found = float(line.split()[1]) * 1024.0
                    break
    except OSError:
        pass
    if found is None:
        try:
            found = float(os.sysconf("SC_PHYS_PAGES")) * float(os.sysconf("SC_PAGE_SIZE"))
        except (ValueError, OSError, AttributeError):
            pass
    cgroups = (("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory.current"),  # v2, then v1
               ("/sys/fs/cgroup/memory/memory.limit_in_bytes", "/sys/fs/cgroup/memory/memory.usage_in_bytes"))
    for path, used_path in cgroups:
        try:
            with open(path) as f:
                limit = f.read().strip()
            if limit == "max" or float(limit) >= 2.0**60:
                continue
            with open(used_path) as f:
                left = float(limit) - float(f.read().strip())
            found = left if found is None else min(found, left)
        except (OSError, ValueError):
            continue
    return found


def check_dense_memory(scene, available=None):
    """Refuse (ValueError naming N and the largest N that fits) a scene whose dense Hessian does
    not fit: ``dense_memory_bytes(scene.n_dof)`` plus PROCESS_BASE_BYTES against ``available``
    bytes (default ``available_memory_bytes()``; unknown: no check). scene: any object with
    ``n_dof`` and ``n_nodes``. Returns the estimate in bytes."""
    need = dense_memory_bytes(scene.n_dof)
    avail = available_memory_bytes() if available is None else float(available)
    if avail is None or need + PROCESS_BASE_BYTES <= avail:
        return need
    n_nodes = int(scene.n_nodes)
    per_node = scene.n_dof / n_nodes
    # Largest n with 8 c n^2 + b n <= avail - base, then the nodes it allows.
    a, b, c = 8.0 * DENSE_HESSIAN_COPIES, float(DENSE_BYTES_PER_DOF), -(avail - PROCESS_BASE_BYTES)
    n_max = (-b + math.sqrt(max(b * b - 4.0 * a * c, 0.0))) / (2.0 * a) if c < 0.0 else 0.0
    n_nodes_max = int(math.floor(n_max / per_node))
    while n_nodes_max > 0 and dense_memory_bytes(math.ceil(per_node * n_nodes_max)) + PROCESS_BASE_BYTES > avail:
        n_nodes_max -= 1
    gb = lambda v: f"{v / 1e9:.0f} GB" if v >= 10e9 else f"{v / 1e9:.1f} GB"  # noqa: E731
    advice = f"use N at most {n_nodes_max}" if n_nodes_max > 0 else "no N fits"
    raise ValueError(
        f"N {n_nodes} needs about {gb(need)} of memory for the dense Hessian ({scene.n_dof} DOFs: the Newton "
        f"corrector holds ~{DENSE_HESSIAN_COPIES:g} copies of the {scene.n_dof} x {scene.n_dof} matrix); this machine "
        f"has {gb(avail)} available: {advice}")

