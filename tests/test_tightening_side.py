"""Issue 16, defect 8: the tightening side of an achiral knot whose two sides are mirror images
was named by a 2e-8 mm difference in radius of gyration; such sides are now 'equal'."""
import math
import pathlib

import numpy as np

from jaxrod.studies import atlas
from jaxrod.studies.critical_summary import summarise_critical, tightening_side

RESULTS = pathlib.Path(__file__).resolve().parent.parent / "benchmarks" / "results" / "atlas"


def _table(rg_plus, rg_minus, contacts_plus, contacts_minus, rg0=40.0):
    """A symmetric branch from phi = 0 to +-2 pi on each side, with its last radius of gyration
    and contact count per side."""
    phi = np.array([0.0, math.pi, 2 * math.pi, 0.0, -math.pi, -2 * math.pi])
    return {"phi": phi, "branch": np.array(["symmetric+"] * 3 + ["symmetric-"] * 3),
            "radius_of_gyration": np.array([rg0, rg0, rg_plus, rg0, rg0, rg_minus]),
            "contact_count": np.array([100, 100, contacts_plus, 100, 100, contacts_minus], dtype=float)}


def _summary(table):
    critical = {"instabilities": [{"direction": "plus", "phi": 6.4 * math.pi, "phi_error": 1e-4, "dlambda_dphi": -1.0},
                                  {"direction": "minus", "phi": -6.4 * math.pi, "phi_error": 1e-4,
                                   "dlambda_dphi": 1.0}]}
    summarise_critical(critical, table)
    return critical


def test_mirror_image_sides_are_equal_not_labelled_by_round_off():
    # The figure-eight's case: the same contacts, radii of gyration 2e-8 mm apart.
    c = _summary(_table(40.5, 40.5 + 2e-8, 96, 96))
    assert c["tightening_side"] == "equal"
    assert c["phi_tightening"] is None and c["phi_opening"] is None


def test_sides_that_differ_are_named():
    c = _summary(_table(39.0, 41.0, 113, 20))  # the trefoil: pairs in contact 100 -> 113 / -> 20
    assert c["tightening_side"] == "phi>0" and c["phi_tightening"] == 6.4 * math.pi
    # Equal contacts: the radius of gyration decides, when it differs by more than round-off;
    # the side whose knot shrinks (loses radius of gyration) tightens.
    c = _summary(_table(40.0 - 1e-3, 40.0 + 1e-3, 96, 96))
    assert c["tightening_side"] == "phi>0"
    assert tightening_side({"plus": (0, 1e-3), "minus": (0, -1e-3)}, scale=40.0) == "minus"


def test_the_atlas_calls_the_mirror_symmetric_figure_eight_equal_and_the_trefoil_not():
    sides = atlas.tightening_sides(atlas.read_atlas(str(RESULTS)))
    # 4_1 relaxes to a mirror-symmetric shape for D/L >= 0.02 (Wr(0) = 0): phi+* = -phi-*.
    assert all(sides[("4_1", r, 101)] == "equal" for r in (0.02, 0.0274, 0.03, 0.035))
    assert all(sides[("3_1", r, 101)] == "minus" for r in (0.01, 0.02, 0.0274, 0.035))
    # The loose figure-eights relax to chiral shapes (Wr(0) = +0.021, -0.005): their sides differ.
    assert sides[("4_1", 0.01, 101)] in ("plus", "minus")
