"""Force control: a dead load T pulls the far clamp along the axis (potential -T times the
clamp's displacement along the axis); its position is a degree of freedom, either along the axis
only (``end="slide"``) or in space (``end="free"``), while the clamp's direction and rotation stay
imposed."""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from ...model.hessian import scaled_hessian as structured_scaled_hessian
from ...solve.solvers import DampedNewton, minimise
from ...validation import check_finite, check_positive
from .compiled import f64, offset_coupling, rod_gradients, rod_hessian
from .equilibria import host, newton
from .resolution import check_rotation_resolution
from .scene import EndLoadedRod, with_end_offset


_BASES = {"slide": 1, "free": 3}


def _offset_basis(scene, end):
    """(k, 3) directions in which the loaded end may move: the axis, or the three axes of space."""
    if end == "slide":
        return jnp.asarray(scene.axis)[None, :]
    return jnp.eye(3)


def _force_split(scene, u):
    n = scene.n_dof
    return u[:n], u[n:]


def force_energy(u, args):
    """Scaled energy of the force-loaded rod: u = [scaled rod DOFs (n,), end offset coordinates
    (k,) in units of the edge length]; args = (scene, phi, T, nbr, basis (k, 3)). The potential of
    the dead load is -T * (end offset . axis)."""
    scene, phi, T, nbr, basis = args
    ur, w = _force_split(scene, u)
    off = (w * scene.length_scale) @ basis
    rod = with_end_offset(scene, off)
    return rod.scaled_energy(ur, phi, nbr) - T * jnp.dot(off, scene.axis) / scene.energy_scale


_force_grad = jax.grad(force_energy)


def force_zero_modes(u, args):
    """(n + k, 1): the rigid rotation about the clamp axis (interior nodes and, for a free end,
    the end offset), in the scaled unknowns: an exact symmetry, as for ``EndLoadedRod``."""
    scene, phi, T, nbr, basis = args
    ur, w = _force_split(scene, u)
    off = (w * scene.length_scale) @ basis
    rod = with_end_offset(scene, off)
    z = rod.scaled_zero_modes(ur, phi)[:, 0]
    zw = basis @ jnp.cross(scene.axis, off) / scene.length_scale
    return jnp.concatenate([z, zw])[:, None]


def force_hessian(u, args):
    """Exact Hessian of ``force_energy``: the rod block by the structured assembly
    (``jaxrod.model.hessian``) at the current end position, the k end rows and columns by k
    Hessian-vector products."""
    scene, phi, T, nbr, basis = args
    ur, w = _force_split(scene, u)
    n, k = ur.shape[0], w.shape[0]
    rod = with_end_offset(scene, (w * scene.length_scale) @ basis)
    h_rr = structured_scaled_hessian(rod, ur, phi, nbr)
    e_w = jnp.concatenate([jnp.zeros((k, n)), jnp.eye(k)], axis=1)
    cols = jax.vmap(lambda e: jax.jvp(lambda uu: _force_grad(uu, args), (u,), (e,))[1])(e_w)  # (k, n + k)
    h = jnp.zeros((n + k, n + k), dtype=u.dtype).at[:n, :n].set(h_rr).at[n:, :].set(cols).at[:, n:].set(cols.T)
    return 0.5 * (h + h.T)


@dataclass(frozen=True)
class ForceEquilibrium:
    """An equilibrium of a ``ForceLoadedRod``: u (scaled DOFs, the end's included), q (physical rod
    DOFs), x (N, 3) nodes, end_offset (3,), extension (end offset along the axis: negative when the
    ends come closer), T, phi, M (axial moment dE/dphi), Wr, Tw, Lk, energy (rod only),
    grad_norm, converged, iterations, eigenvalues (lowest, scaled), morse (negative count)."""

    u: np.ndarray
    q: np.ndarray
    x: np.ndarray
    end_offset: np.ndarray
    extension: float
    T: float
    phi: float
    M: float
    Wr: float
    Tw: float
    Lk: float
    energy: float
    grad_norm: float
    converged: bool
    iterations: int
    eigenvalues: np.ndarray
    morse: int


class ForceLoadedRod:
    """A rod clamped at its near end, with a dead load T pulling its far clamp along the axis and
    the far clamp's material frame turned by phi. ``end``: "slide" (the far clamp moves along the
    axis only) or "free" (it moves in space; its edge stays along the axis). ``rod``: an
    ``EndLoadedRod`` (``shortened_rod(..., shortening=0)``) giving material, N and contact.

    The unknowns are u = [rod's scaled DOFs, end offset in edge lengths (1 or 3)]; T and phi are
    parameters (``problem`` gives the BifurcationProblem in either)."""

    def __init__(self, rod, end="slide"):
        if end not in _BASES:
            raise ValueError(f"end must be 'slide' or 'free', got {end!r}")
        if not isinstance(rod, EndLoadedRod):
            raise TypeError("rod must be an EndLoadedRod (jaxrod.studies.endloads.shortened_rod)")
        self.rod = with_end_offset(rod, jnp.zeros(3))
        self.end = end
        self.k = _BASES[end]
        self.basis = _offset_basis(self.rod, end)
        self._basis = np.asarray(self.basis, dtype=float)
        self._axis = np.asarray(self.rod.axis, dtype=float)
        self._ls = float(self.rod.length_scale)
        self._es = float(self.rod.energy_scale)

    def args(self, phi, T, nbr=None):
        return (self.rod, jnp.asarray(phi, dtype=jnp.float64), jnp.asarray(T, dtype=jnp.float64), nbr, self.basis)

    def u_from(self, q, offset):
        """Scaled unknowns from rod DOFs q and the end offset (3,) (its part along the allowed basis)."""
        w = np.asarray(self.basis) @ np.asarray(offset, dtype=float) / float(self.rod.length_scale)
        return np.concatenate([np.asarray(self.rod.to_scaled(np.asarray(q, dtype=float))), w])

    def straight(self, T, phi=0.0):
        """The straight state under tension T twisted by phi: uniform stretch T/EA, uniform twist."""
        strain = float(T) / float(self.rod.material.EA)
        # the clamped end edges are rigid: the N - 3 interior edges carry the stretch
        ext = strain * float(self.rod.length_scale) * (self.rod.n_nodes - 3)
        a = np.asarray(self.rod.axis)
        xc = np.asarray(self.rod.x_clamped)
        n_free = self.rod.n_nodes - 4
        q = np.asarray(self.rod.q_init).copy()
        start, stop = xc[1], xc[2] + ext * a
        frac = np.arange(1, n_free + 1) / (n_free + 1)
        q[:3 * n_free] = (start[None, :] + frac[:, None] * (stop - start)[None, :]).ravel()
        n_edges = self.rod.n_nodes - 1
        q[3 * n_free:] = float(phi) * np.arange(1, n_edges - 1) / (n_edges - 1)
        return self.u_from(q, ext * a)

    def solve(self, T, phi, u0, method="newton", gtol=1e-8, max_steps=None, throw=True, k=6):
        """Equilibrium at (T, phi) from u0: "newton" (nearest stationary point) or "damped" (a
        minimiser: damped Newton). Returns a ``ForceEquilibrium`` with its stability.
        Refused: non-positive or non-finite T, non-finite phi or u0, a rod too coarse for the
        end rotation (N named)."""
        from ...solve.solvers import ConvergenceError  # noqa: PLC0415

        T = check_positive("T", T)
        phi = check_finite("phi", phi)
        check_positive("gtol", gtol)
        check_rotation_resolution(self.rod.n_nodes, phi)
        u0 = np.asarray(u0, dtype=float)
        if u0.shape != (self.rod.n_dof + self.k,):
            raise ValueError(f"u0 must have shape ({self.rod.n_dof + self.k},) (rod DOFs and end offset), got {u0.shape}")
        if not np.all(np.isfinite(u0)):
            raise ValueError("u0 must be finite")
        if method == "newton":
            # the neighbourhood is frozen during Newton's steps and rebuilt at the result, until consistent
            u = u0
            for _ in range(5):
                nbr = self.neighbourhood(u, phi)
                sol = newton(None, self.hessian, u, (phi, T, nbr), gtol=gtol,
                             max_steps=200 if max_steps is None else max_steps, throw=False,
                             value_and_grad=self.value_and_grad)
                u = sol.y
                if not sol.converged:
                    break
                _, g = self.value_and_grad(u, (phi, T, self.neighbourhood(u, phi)))
                gnorm = float(np.max(np.abs(g)))
                if gnorm <= gtol:
                    break
                sol = dataclasses.replace(sol, grad_norm=gnorm, converged=False)
            if throw and not sol.converged:
                raise ConvergenceError(f"capped Newton did not converge: {sol!r}", solution=sol)
        elif method == "damped":
            solver = DampedNewton(hessian=force_hessian, zero_modes=force_zero_modes)
            sol = minimise(force_energy, u0, self.args(phi, T), solver, gtol, max_steps, throw=throw)
        else:
            raise ValueError(f"method must be 'newton' or 'damped', got {method!r}")
        return self.equilibrium(sol.y, T, phi, sol=sol, k=k)

    # host compositions of the displacement-controlled rod's compiled programs
    def _state(self, u):
        u = np.asarray(u, dtype=float)
        n = self.rod.n_dof
        off = self._ls * (u[n:] @ self._basis)
        return with_end_offset(self.rod, off), u[:n], off

    def neighbourhood(self, u, phi):
        """The rod's neighbourhood (writhe reference, contact candidates) at the unknowns u."""
        rod, ur, _ = self._state(u)
        return rod.neighbourhood(np.asarray(rod.from_scaled(ur)), phi)

    @host
    def value_and_grad(self, u, args):
        """(``force_energy`` at u, its gradient (n + k,)); args = (phi, T, neighbourhood)."""
        phi, T, nbr = args
        rod, ur, off = self._state(u)
        val, gu, goff, _, _ = rod_gradients(rod, ur, phi, nbr)
        value = float(val) - float(T) * float(off @ self._axis) / self._es
        gw = self._basis @ (np.asarray(goff) - float(T) * self._axis) * self._ls / self._es
        return value, np.concatenate([np.asarray(gu), gw])

    @host
    def hessian(self, u, args):
        """(exact Hessian of ``force_energy`` (n + k, n + k), the zero mode (n + k, 1)); args as
        ``value_and_grad``."""
        phi, T, nbr = args
        rod, ur, off = self._state(u)
        h_rr, z_r = rod_hessian(rod, ur, phi, nbr)
        c = np.asarray(offset_coupling(rod, f64(ur), f64(phi), nbr))
        n, b = ur.shape[0], self._basis
        cols = self._ls * c[:n] @ b.T
        hww = self._ls ** 2 * b @ c[n:] @ b.T
        h = np.block([[np.asarray(h_rr), cols], [cols.T, 0.5 * (hww + hww.T)]])
        zw = b @ np.cross(self._axis, off) / self._ls
        return h, np.concatenate([np.asarray(z_r)[:, 0], zw])[:, None]

    def equilibrium(self, u, T, phi, sol=None, k=6):
        from ...solve.equilibrium import _diagnostics  # noqa: PLC0415

        u = np.asarray(u, dtype=float)
        rod, ur, off = self._state(u)
        nbr = rod.neighbourhood(np.asarray(rod.from_scaled(ur)), phi)
        args = (phi, T, nbr)
        _, g = self.value_and_grad(u, args)
        h, z = self.hessian(u, args)
        _, _, _, M, _ = rod_gradients(rod, ur, phi, nbr)
        q, x, _, terms, tw = jax.device_get(_diagnostics(rod, f64(ur), f64(phi), nbr))
        nz = np.linalg.norm(z)
        if nz > 0.0:  # lift the axial rotation (exact zero mode) above the spectrum
            z = z / nz
            p = np.eye(h.shape[0]) - z @ z.T
            h = p @ h @ p + (np.max(np.abs(np.diag(h))) + 1.0) * (z @ z.T)
        lam = np.linalg.eigvalsh(h)
        wr = float(nbr.wr_ref)
        tol = 1e-10 * max(float(np.max(np.abs(np.diag(h)))), 1.0)
        return ForceEquilibrium(
            u=u, q=np.asarray(q), x=np.asarray(x), end_offset=np.asarray(off),
            extension=float(np.dot(off, self._axis)), T=float(T), phi=float(phi), M=float(M), Wr=wr, Tw=float(tw),
            Lk=wr + float(tw), energy=float(sum(float(v) for v in terms.values())),
            grad_norm=float(np.max(np.abs(g))),
            converged=True if sol is None else bool(sol.converged), iterations=0 if sol is None else sol.iterations,
            eigenvalues=lam[:k], morse=int(np.sum(lam < -tol)))

    def problem(self, parameter, u0, T, phi):
        """BifurcationProblem in ``parameter`` ("phi" or "T") at fixed other load, started at u0."""
        from ...continuation.arclength import BifurcationProblem  # noqa: PLC0415

        if parameter == "phi":
            return BifurcationProblem(_force_energy_phi, u0, float(phi), (self.rod, jnp.asarray(float(T)), None,
                                                                          self.basis), jacobian=_force_jacobian_phi)
        if parameter == "T":
            return BifurcationProblem(_force_energy_T, u0, float(T), (self.rod, jnp.asarray(float(phi)), None,
                                                                      self.basis), jacobian=_force_jacobian_T)
        raise ValueError(f"parameter must be 'phi' or 'T', got {parameter!r}")


def _force_energy_phi(u, p, args):
    scene, T, nbr, basis = args
    return force_energy(u, (scene, p, T, nbr, basis))


def _force_jacobian_phi(u, p, args):
    scene, T, nbr, basis = args
    return force_hessian(u, (scene, p, T, nbr, basis))


def _force_energy_T(u, p, args):
    scene, phi, nbr, basis = args
    return force_energy(u, (scene, phi, p, nbr, basis))


def _force_jacobian_T(u, p, args):
    scene, phi, nbr, basis = args
    return force_hessian(u, (scene, phi, p, nbr, basis))
