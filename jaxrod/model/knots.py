"""Point tables of knots: published parametrisations sampled at n points, and the ideal
ropelengths below which a rod of that knot cannot exist. Pure numpy; the scenes are built from
them by ``jaxrod.model.scenes.knot``/``trefoil``."""
from __future__ import annotations

import math

import numpy as np

__all__ = ["IDEAL_TREFOIL_ROPELENGTH", "IDEAL_ROPELENGTH", "KNOT_NAMES", "trefoil_points", "knot_points"]

TWO_PI = 2.0 * math.pi

# Ropelength L/D of the ideal (tightest) trefoil (Baranska, Przybyl, Pieranski 2008: 16.372).
IDEAL_TREFOIL_ROPELENGTH = 16.372


def trefoil_points(n, chirality="right"):
    """(n,3) points of the trefoil (sin t + 2 sin 2t, cos t - 2 cos 2t, -+sin 3t). With -sin 3t this
    parametrisation is left-handed (writhe ~ -3.35); 'right' flips z."""
    if chirality not in ("right", "left"):
        raise ValueError(f"chirality must be 'right' or 'left', got {chirality!r}")
    t = TWO_PI * np.arange(n) / n
    z = -np.sin(3 * t) if chirality == "left" else np.sin(3 * t)
    return np.stack([np.sin(t) + 2 * np.sin(2 * t), np.cos(t) - 2 * np.cos(2 * t), z], axis=1)


# Ropelength L/D of the ideal (tightest) knots, below which a rod cannot be tied in that knot: the
# trefoil (Baranska, Przybyl, Pieranski 2008); 4_1, 5_1, 5_2 (Ashton, Cantarella, Piatek, Rawdon,
# Experimental Mathematics 20 (2011)).
IDEAL_ROPELENGTH = {"3_1": IDEAL_TREFOIL_ROPELENGTH, "4_1": 21.04, "5_1": 23.55, "5_2": 24.68}
KNOT_NAMES = {"3_1": "trefoil", "4_1": "figure-eight knot", "5_1": "cinquefoil", "5_2": "three-twist knot"}


def knot_points(name, n):
    """(n, 3) points of a published parametrisation of the knot ``name`` (t = 2 pi k / n):
    3_1 the trefoil (sin t + 2 sin 2t, cos t - 2 cos 2t, sin 3t); 4_1 the figure-eight knot
    ((2 + cos 2t) cos 3t, (2 + cos 2t) sin 3t, sin 4t); 5_1 the cinquefoil, torus knot T(2, 5)
    ((2 + cos 5t) cos 2t, (2 + cos 5t) sin 2t, sin 5t); 5_2 the three-twist knot as the Lissajous
    knot (cos(3t + 0.7), cos(2t + 0.2), cos 7t) (Bogle, Hearst, Jones, Stoilov 1994)."""
    if name not in IDEAL_ROPELENGTH:
        raise ValueError(f"knot must be one of {', '.join(IDEAL_ROPELENGTH)}, got {name!r}")
    t = TWO_PI * np.arange(n) / n
    if name == "3_1":
        return trefoil_points(n)
    if name == "4_1":
        return np.stack([(2 + np.cos(2 * t)) * np.cos(3 * t), (2 + np.cos(2 * t)) * np.sin(3 * t), np.sin(4 * t)], axis=1)
    if name == "5_1":
        return np.stack([(2 + np.cos(5 * t)) * np.cos(2 * t), (2 + np.cos(5 * t)) * np.sin(2 * t), np.sin(5 * t)], axis=1)
    return np.stack([np.cos(3 * t + 0.7), np.cos(2 * t + 0.2), np.cos(7 * t)], axis=1)
