"""Linear-algebra backends: everything the continuation does with the Jacobian goes through one.

A backend is chosen once, on the problem. ``DenseBackend`` assembles J (n, n) with ``jax.jacfwd``
and uses ``jnp.linalg``; a structured backend (block-tridiagonal rod Hessian, pinned gauge) only has
to provide the same three methods.
"""
from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np


@jax.jit
def _bordered(A, B, C, D, f, g):
    M = jnp.block([[A, B], [C.T, D]])
    z = jnp.linalg.solve(M, jnp.concatenate([f, g]))
    return z[: A.shape[0]], z[A.shape[0]:]


@dataclass(frozen=True)
class DenseBackend:
    """Dense J from ``jax.jacfwd``; solves and eigenpairs by ``jnp.linalg``. Stateless: every
    instance is equal (a problem's jitted functions are shared per backend, see ``problem``)."""

    def jacobian(self, f, u):
        """J = df/du (n, n) of f: (n,) -> (n,); traceable (called inside jit)."""
        return jax.jacfwd(f)(u)

    def bordered_solve(self, A, b, c, d, f, g):
        """Solve [[A, b], [c^T, d]] [x; y] = [f; g].

        A (m, m); b, c (m,) with d, g scalars (y scalar), or b, c (m, k) with d (k, k), g (k,)
        (y (k,)). Traceable. The bordered matrix is regular at a fold, where A alone is singular.
        """
        if jnp.ndim(b) == 1:
            x, y = _bordered(A, b[:, None], c[:, None], jnp.reshape(d, (1, 1)), f, jnp.reshape(g, (1,)))
            return x, y[0]
        return _bordered(A, b, c, jnp.asarray(d), f, jnp.asarray(g))

    def spectrum(self, J, n_keep, n_zero, rtol):
        """(values (n_keep,), vectors (n, n_keep), Morse index) of the symmetric J.

        The n_zero eigenvalues of smallest |lambda| (gauge zero modes) are removed first. The Morse
        index counts lambda < -rtol * ||J||_2 over the whole spectrum: the band scales with J, so it
        does not hide real instabilities of a stiff problem (a structured backend would count the
        inertia of an LDL^T factorisation instead).
        """
        vals, vecs = (np.asarray(a) for a in jnp.linalg.eigh(J))
        if n_zero:
            keep = np.sort(np.argsort(np.abs(vals))[n_zero:])
            vals, vecs = vals[keep], vecs[:, keep]
        scale = max(float(np.max(np.abs(vals), initial=0.0)), 1e-300)
        return vals[:n_keep], vecs[:, :n_keep], int(np.sum(vals < -rtol * scale))
