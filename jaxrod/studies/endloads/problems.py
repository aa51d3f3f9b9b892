"""End-loaded rods as ``BifurcationProblem``s of the pseudo-arclength engine
(``jaxrod.continuation.arclength``): the shortening or the end rotation as the parameter."""
from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from ...model.hessian import scaled_hessian as structured_scaled_hessian
from .scene import with_shortening


def shortening_energy(u, p, args):
    """Scaled energy of an ``EndLoadedRod`` with p = shortening; args = (scene, phi): a
    ``BifurcationProblem`` energy (jaxrod.continuation.arclength)."""
    scene, phi = args
    return with_shortening(scene, p).scaled_energy(u, phi)


def shortening_jacobian(u, p, args):
    scene, phi = args
    return structured_scaled_hessian(with_shortening(scene, p), u, phi, None)


def rotation_energy(u, p, args):
    """Scaled energy with p = end rotation phi; args = (scene,)."""
    (scene,) = args
    return scene.scaled_energy(u, p)


def rotation_jacobian(u, p, args):
    (scene,) = args
    return structured_scaled_hessian(scene, u, p, None)


def shortening_problem(scene, q0, phi):
    """BifurcationProblem with p = shortening (start: scene's shortening), phi fixed; u = scaled q."""
    from ...continuation.arclength import BifurcationProblem  # noqa: PLC0415

    return BifurcationProblem(shortening_energy, scene.to_scaled(np.asarray(q0, dtype=float)),
                              float(scene.shortening), (scene, jnp.asarray(float(phi))), jacobian=shortening_jacobian)


def rotation_problem(scene, q0, phi0):
    """BifurcationProblem with p = end rotation phi at the scene's shortening; u = scaled q."""
    from ...continuation.arclength import BifurcationProblem  # noqa: PLC0415

    return BifurcationProblem(rotation_energy, scene.to_scaled(np.asarray(q0, dtype=float)), float(phi0), (scene,),
                              jacobian=rotation_jacobian)
