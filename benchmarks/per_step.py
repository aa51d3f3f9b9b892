"""The cost of one step of a continuation, per backend and node count: what a Newton iteration and a
stability analysis cost on command 1's trefoil (D = 8, L = 292, with contact) and on Michell's ring
(no contact), for N = 61, 121, 241, 481 and 961.

    python benchmarks/per_step.py                 # the full table (the dense backend up to N = 481)
    python benchmarks/per_step.py --smoke         # N = 41, each backend once

For each scene and N: the relaxed state at phi = 0 (the trefoil) or just below Michell's threshold
(the ring, 5 pi), then for each backend of ``jaxrod.linalg.backend`` that holds the scene, the best
of ``REPEATS`` calls (after a first call that compiles) of:

- ``gradient``: the scaled energy's gradient (one jitted program, the same for every backend);
- ``factorise``: the Hessian assembled and factorised (``backend.factorise``);
- ``solve``: one solve with the factorisation (a Newton direction);
- ``inertia``: the count of negative eigenvalues of the projected Hessian;
- ``eig4``: its lowest 4 eigenpairs, the zero modes deflated.

Each part is timed on a fresh factorisation (a backend may defer work to its first use) and
reported less the factorisation's own time. A Newton iteration is gradient + factorise + solve; a
stability analysis (inertia and eig4 on one factorisation) is timed as a whole. The dense backend stops at ``DENSE_MAX_N`` (its n x n Hessian at N = 961 is 118 MB and one
eigen-analysis takes seconds). Wall times on this machine, BLAS threads 1. Writes
benchmarks/results/per_step.md and per_step.json.
"""
import os

for _v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import json  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402

import numpy as np  # noqa: E402

from _bench import SMOKE, markdown, pick, results_dir, with_provenance  # noqa: E402  (benchmarks/ is on the path)

NODES = pick((61, 121, 241, 481, 961), (41,))
DENSE_MAX_N = 481
REPEATS = pick(7, 2)
PARTS = ("gradient", "factorise", "solve", "inertia", "eig4")


def best_ms(call):
    """The best of REPEATS calls of ``call`` (after one that compiles), in ms."""
    call()
    times = []
    for _ in range(REPEATS):
        t = time.perf_counter()
        call()
        times.append(time.perf_counter() - t)
    return 1e3 * min(times)


def scenes(N):
    import jaxrod as jr

    return (("trefoil", jr.trefoil(D=8.0, L=292.0, N=N), 0.0), ("ring", jr.michell_ring(N=N), 5.0 * math.pi))


def measure(scene, phi):
    """{backend: {part: ms}} at the relaxed state of ``scene`` at ``phi``."""
    import jax

    import jaxrod as jr
    from jaxrod.linalg.backend import Banded, Dense, LinalgOptions, Sparse

    with warnings.catch_warnings():  # the ring's twisted circle is one branch from 0 to 5 pi: no jump to fear
        warnings.filterwarnings("ignore", message="one solve at phi")
        e = jr.equilibrium(scene, phi)
    u = np.asarray(scene.to_scaled(np.asarray(e.q)))
    nbr = e.neighbourhood
    gradient = jax.jit(jax.grad(scene.scaled_energy))
    g = np.asarray(gradient(u, phi, nbr))
    gradient_ms = best_ms(lambda: np.asarray(gradient(u, phi, nbr)))  # the same program for every backend
    rows = {}
    for backend in (Dense, Banded, Sparse):
        b = backend(LinalgOptions())
        if not b.supports(scene) or (backend is Dense and scene.n_nodes > DENSE_MAX_N):
            continue
        def fresh():
            return b.factorise(scene, u, phi, nbr)

        def analysis():
            f = fresh()
            return f.inertia(0.0), f.lowest_eigenpairs(4)

        # each part on a fresh factorisation: a backend may defer work to its first use (the dense
        # one computes the eigenvalues for the inertia once, and keeps them)
        factorise = best_ms(fresh)
        r = rows[b.name] = {"gradient": gradient_ms, "factorise": factorise,
                            "solve": best_ms(lambda: fresh().solve(g)) - factorise,
                            "inertia": best_ms(lambda: fresh().inertia(0.0)) - factorise,
                            "eig4": best_ms(lambda: fresh().lowest_eigenpairs(4)) - factorise,
                            "stability": best_ms(analysis)}
        r["newton_iteration"] = r["gradient"] + r["factorise"] + r["solve"]
    return rows


def table(results):
    lines = ["| scene | N | DOFs | backend | gradient | factorise | solve | inertia | eig4 | Newton iteration | "
             "stability analysis |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        for name, t in r["backends"].items():
            lines.append(f"| {r['scene']} | {r['N']} | {r['n_dof']} | {name} | "
                         + " | ".join(f"{t[p]:.2f}" for p in PARTS + ("newton_iteration", "stability")) + " |")
    return lines


def main():
    out = results_dir()
    os.makedirs(out, exist_ok=True)
    results = []
    for N in NODES:
        for name, scene, phi in scenes(N):
            t = time.perf_counter()
            rows = measure(scene, phi)
            results.append({"scene": name, "N": N, "n_dof": int(scene.n_dof), "phi": phi, "backends": rows})
            print(f"{name} N = {N}: " + ", ".join(f"{b} Newton {r['newton_iteration']:.2f} ms, stability "
                                                   f"{r['stability']:.2f} ms" for b, r in rows.items())
                  + f" ({time.perf_counter() - t:.0f} s)", flush=True)
    machine = f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    with open(os.path.join(out, "per_step.json"), "w") as f:
        json.dump(with_provenance({"machine": machine, "repeats": REPEATS, "results": results}), f, indent=2)
    text = markdown(["# The cost of one continuation step, per backend and node count", "",
                     f"Best of {REPEATS} calls in ms (wall, after a first call that compiles); {machine}, BLAS "
                     f"threads {os.environ.get('OPENBLAS_NUM_THREADS')}. Newton iteration = gradient + factorise "
                     "+ solve; stability analysis = factorise + inertia + the lowest 4 eigenpairs. The trefoil "
                     "(D = 8, L = 292, contact) at its relaxed state at phi = 0; Michell's ring at 5 pi. The "
                     f"dense backend up to N = {DENSE_MAX_N}; the banded one holds no contact.", "", *table(results)])
    with open(os.path.join(out, "per_step.md"), "w") as f:
        f.write(text)
    print(text)


if __name__ == "__main__":
    main()
