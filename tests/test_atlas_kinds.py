"""Every end of the atlas is classified: a fold or branch point located on its extended system,
or a snap with the states on both sides of it; never a bare 'jump'. The figure-eight knot (4_1) at
two slendernesses, both sides: its mirror-symmetric sides where its start is mirror-congruent to
itself, and the chirality of its start reported where it is not."""
import json
import math
import pathlib

import numpy as np
import pytest

import jaxrod as jr
from jaxrod.measure.chirality import ACHIRAL_TOL
from jaxrod.studies import atlas

# The validation tier (-m validation): whole studies of the figure-eight and the trefoil.
pytestmark = pytest.mark.validation

PI = math.pi
REPO = pathlib.Path(__file__).resolve().parent.parent
RATIOS, N = [0.02, 0.025], 61  # both sides end near 7.2 pi (a fold at N = 61)
SETTINGS = atlas.AtlasSettings(span=8.0 * PI)


@pytest.fixture(scope="module")
def rows(tmp_path_factory):
    out = tmp_path_factory.mktemp("atlas_4_1")
    return out, atlas.run_atlas(["4_1"], RATIOS, N, settings=SETTINGS, out=str(out))


def test_every_end_of_the_figure_eight_is_located_or_a_snap(rows):
    out, found = rows
    assert [(r["D_over_L"], r["side"]) for r in found] == [(0.02, "plus"), (0.02, "minus"), (0.025, "plus"),
                                                           (0.025, "minus")]
    for r in found:
        assert r["kind"] in ("fold", "branch_point", "snap"), r["reason"]
        assert 6.5 < abs(r["phi_star"]) / PI < 8.0 and math.copysign(1.0, r["phi_star"]) == (1 if r["side"] == "plus" else -1)
        if r["kind"] == "snap":
            assert r["located"] == "no" and (out / "states").is_dir()
        else:
            assert r["located"] == "yes" and math.isnan(r["snap_moved"])
            assert abs(r["phi_star"] - r["phi_study"]) <= 2.0 * r["phi_error"] + 1e-9


def test_mirror_congruent_starts_have_mirror_sides_and_chiral_ones_are_reported(rows):
    _, found = rows
    for ratio in RATIOS:
        plus, minus = (next(r for r in found if r["D_over_L"] == ratio and r["side"] == s) for s in ("plus", "minus"))
        assert plus["mirror_distance_start"] == minus["mirror_distance_start"]  # one start for both sides
        if plus["mirror_distance_start"] <= ACHIRAL_TOL:
            assert abs(plus["phi_star"] + minus["phi_star"]) <= plus["phi_error"] + minus["phi_error"]
            assert abs(plus["Wr_start"]) < 1e-3
    report = open(atlas.report(rows[0])).read()
    assert "mirror distance" in report
    for r in found:
        word = "achiral" if r["mirror_distance_start"] <= ACHIRAL_TOL else "chiral"
        assert f"{r['mirror_distance_start']:.1e} ({word})" in report


def test_a_jump_left_unlocated_is_a_snap_with_both_states(tmp_path):
    """Without the location on the extended system, the study's jump is classified by where the
    rod goes: a stable state at the bracket's far end, with Lk kept, away from the branch."""
    out = tmp_path / "snap"
    settings = atlas.AtlasSettings(span=8.0 * PI, tol=1e-2 * PI, locate=False)
    (row,) = atlas.run_atlas(["4_1"], [0.025], N, settings=settings, out=str(out), sides="plus")
    assert row["kind"] == "snap" and row["located"] == "no", row["reason"]
    states = np.load(out / "states" / f"4_1_0.025_N{N}_plus.npz")
    scene = jr.knot("4_1", D=0.025, L=1.0, N=N, nu=0.5, contact_stiffness=100.0, Lk0=row["Lk0"])
    before, after = float(states["phi_before"]), float(states["phi_after"])
    assert 0.0 < after - before <= 2.0 * row["phi_error"] + 1e-12  # the bracket, in which the rod snaps
    assert states["q_before"].shape == states["q_after"].shape == (scene.n_dof,)
    assert row["snap_moved"] > 0.5 * 0.025  # further than jump_tol (D / 2) from the branch
    e_after = jr.equilibrium(scene, after, start=states["q_after"])
    assert e_after.stability.stable and abs(e_after.Wr - row["Wr_after"]) < 1e-6
    assert abs(e_after.Lk - (scene.Lk0 + after / (2 * PI))) < 1e-8
    assert np.max(np.abs(np.asarray(e_after.q) - states["q_after"])) < 1e-6  # it is an equilibrium already


def test_the_figure_eight_has_mirror_image_ends_with_error_bars():
    """The committed accuracy-mode run (benchmarks/figure_eight_accuracy.py): at D/L = 0.02 both
    sides converge to 0.05 pi with the order measured, from a start that is its own mirror image,
    and agree with phi*+ = -phi*- within their error bars; at D/L = 0.015 no error bar is claimed."""
    data = json.loads((REPO / "benchmarks" / "results" / "figure_eight_accuracy.json").read_text())
    cases = {c["D_over_L"]: c for c in data["cases"]}
    tight = cases[0.02]
    assert tight["mirror_distance_start"] <= ACHIRAL_TOL and tight["start"] == "achiral"
    plus, minus = tight["sides"]["plus"], tight["sides"]["minus"]
    for side in (plus, minus):
        ext = side["extrapolation"]
        assert side["reached"] and side["error"] <= 0.05 * PI and ext["order_measured"] and ext["asymptotic"]
        assert len(ext["N"]) >= 3 and abs(side["levels"][-1]["phi_star"] - side["phi_star"]) <= 2 * side["error"]
    assert plus["phi_star"] > 0 > minus["phi_star"]
    assert abs(plus["phi_star"] + minus["phi_star"]) <= plus["error"] + minus["error"]
    loose = cases[0.015]
    assert not all(s["reached"] for s in loose["sides"].values())
    for c in data["cases"]:
        assert c["start"] == ("achiral" if c["mirror_distance_start"] <= ACHIRAL_TOL else "chiral")
