"""Two-parameter continuation: a located fold followed in a second parameter mu.

The fold curve is the solution set of the minimally augmented system G(u, p, mu) = (F, sigma) = 0
(see locate.py), n+1 equations in (u, p, mu); it is followed by the same pseudo-arclength core
with x = (u, p) and lam = mu. At each point the implicit function theorem gives
dp*/dmu from one bordered solve  [[J, F_p], [sigma_u^T, sigma_p]] [du; dp] = -[F_mu; sigma_mu],
with sigma_mu = -w^T J_mu w (exact, by JAX). The fold-curve corrector assembles its (n+1) Jacobian
densely (a structured backend would need a doubly bordered solve there).
"""
from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from .corrector import advance, correct, tangent
from .results import ContinuationError, Result


@dataclass
class FoldCurve:
    """Fold points along mu: mu, p, dp_dmu (IFT), residual (m,); u, v (m, n); result, message."""

    mu: np.ndarray
    p: np.ndarray
    u: np.ndarray
    v: np.ndarray
    dp_dmu: np.ndarray
    residual: np.ndarray
    result: Result
    message: str


def fold_curve(problem, fold, set_mu, mu0, alg, opts, *, throw=True):
    """Continue the fold Event ``fold`` of ``problem`` (whose args hold mu = mu0) in mu.

    set_mu(args, mu) -> args must be traceable. opts.ds (signed) is the first step in mu,
    [opts.p_min, opts.p_max] bounds mu, max_steps and the tolerances apply as for continuation.
    """
    be, n, args0 = problem.backend, problem.n, problem.args

    def blocks(u, p, mu, b):
        args = set_mu(args0, mu)
        F, J, Fp = problem._linearise(u, p, args)
        Fmu = jax.jvp(lambda m: problem.F(u, p, set_mu(args0, m)), (mu,), (jnp.ones_like(mu),))[1]
        w, sigma = be.bordered_solve(J, b, b, 0.0, jnp.zeros(n), 1.0)
        grads = jax.grad(lambda x, q, m: jnp.dot(w, problem.hvp(x, q, set_mu(args0, m), w)), argnums=(0, 1, 2))
        gu, gp, gm = grads(u, p, mu)
        return F, J, Fp, Fmu, sigma, -gu, -gp, -gm, w

    blocks = jax.jit(blocks)
    border = [np.asarray(fold.v[:, 0])]  # refreshed with w at each point: the root does not depend on it

    def lin(x, mu):
        F, J, Fp, Fmu, s, su, sp, sm, _ = blocks(x[:-1], x[-1], mu, border[0])
        A = jnp.block([[J, Fp[:, None]], [su[None, :], jnp.reshape(sp, (1, 1))]])
        return jnp.append(F, s), A, jnp.append(Fmu, sm)

    rows = []

    def record(z, res):
        F, J, Fp, Fmu, s, su, sp, sm, w = blocks(z[:-2], z[-2], z[-1], border[0])
        _, dp = be.bordered_solve(J, Fp, su, sp, -Fmu, -sm)
        border[0] = np.asarray(w) / np.linalg.norm(w)
        rows.append((z[-1], z[-2], z[:-2], border[0], float(dp), res))

    t0 = np.zeros(n + 2)
    t0[-1] = np.sign(opts.ds)
    c = correct(be, lin, np.concatenate([fold.u, [fold.p, mu0]]), t0, opts.newton_tol, opts.newton_max_iter)
    result, message = Result.MAX_STEPS, f"stopped after max_steps = {opts.max_steps} steps"
    if not c.converged:
        result, message = Result.CORRECTOR_FAILED, f"the fold did not converge at mu0: residual {c.residual:.3g}"
    else:
        record(c.z, c.residual)
        z, t, ds = c.z, tangent(be, c.lin[1], c.lin[2], t0), abs(opts.ds)
        for _ in range(opts.max_steps):
            step = advance(alg, be, lin, z, t, ds, opts)
            if step is None:
                result = Result.CORRECTOR_FAILED
                message = f"the fold-curve corrector failed down to ds_min = {opts.ds_min:g} at mu = {z[-1]:.12g}"
                break
            z, t, ds = step.z, step.tangent, step.ds_next
            record(z, step.correction.residual)
            if not opts.p_min <= z[-1] <= opts.p_max:
                result, message = Result.BOUNDARY, f"mu = {z[-1]:.12g} left [{opts.p_min:g}, {opts.p_max:g}]"
                break
    cols = list(zip(*rows)) if rows else [[]] * 6
    curve = FoldCurve(*(np.array(col) for col in cols), result, message)
    if throw and result is Result.CORRECTOR_FAILED:
        raise ContinuationError(f"{result.value}: {message}", curve)
    return curve
