"""Issue 16, defect 4: Lk0 = round(writhe of the input) is the twist-free rod only when the input
is close to its relaxed shape. A drawn unknot of writhe -1.02 (a lifted pentagram) was studied
with Lk0 = -1, i.e. one stored turn of twist at "phi = 0", without a word. Now the relaxation at
phi = 0 warns, a writhe near a half-integer warns, and Lk0 can be given (API and --lk0)."""
import math
import warnings

import numpy as np
import pytest

import jaxrod as jr

MAT = jr.Material.from_engineering(0.474, 0.5, 8.0)


def pentagram(lift=0.6):
    """Five points of a star polygon lifted out of its plane: an unknot drawn with writhe -1.02."""
    t = 2 * math.pi * np.arange(5) / 5
    return np.stack([np.cos(2 * t), np.sin(2 * t), lift * np.sin(2 * t) * np.cos(t)], axis=1)


def _relax(scene):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        eq = jr.relax_to_minimum(scene, 0.0)
    return eq, [str(w.message) for w in caught]


def test_a_rod_relaxed_with_a_stored_turn_of_twist_is_flagged_and_lk0_can_be_given():
    drawn = jr.closed_curve(pentagram(), material=MAT, N=61, length=292.0, contact_stiffness=100.0)
    assert drawn.Lk0 == -1.0  # the integer nearest the drawn writhe
    eq, said = _relax(drawn)
    assert eq.stability.stable and abs(eq.Wr) < 1e-6 and eq.Tw == pytest.approx(-1.0, abs=1e-6)  # a twisted circle
    assert len(said) == 1 and "stores Tw = -1.000 turns" in said[0] and "Lk0 = -1" in said[0], said
    assert "twist-free with Lk0 = 0" in said[0] and "--lk0" in said[0]
    # Given, the untwisted rod: no twist stored, no warning.
    given = jr.closed_curve(pentagram(), material=MAT, N=61, length=292.0, contact_stiffness=100.0, Lk0=0)
    eq, said = _relax(given)
    assert said == [] and abs(eq.Tw) < 1e-6 and eq.Lk == pytest.approx(0.0, abs=1e-9)


def test_relax_twist_free_takes_the_linking_number_of_the_untwisted_rod():
    """The pentagram drawn with writhe -1.02 relaxes to a circle: with Lk0 = -1 it stores a turn;
    relax_twist_free re-bases Lk0 on the relaxed writhe (0) and relaxes again, silently."""
    from jaxrod.solve.equilibrium import relax_twist_free

    drawn = jr.closed_curve(pentagram(), material=MAT, N=61, length=292.0, contact_stiffness=100.0)
    said = []
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        scene, eq = relax_twist_free(drawn, progress=said.append)
    assert drawn.Lk0 == -1.0 and scene.Lk0 == 0.0 and scene is not drawn
    assert eq.stability.stable and abs(eq.Tw) < 1e-6 and eq.Lk == pytest.approx(0.0, abs=1e-9)
    assert len(said) == 1 and "Lk0 = -1" in said[0] and "Lk0 = 0 instead" in said[0]
    again, eq_again = relax_twist_free(scene, eq.q)
    assert again is scene and eq_again.energy == pytest.approx(eq.energy, rel=1e-9)  # already right: unchanged


def test_a_writhe_near_a_half_integer_is_flagged():
    t = 2 * math.pi * np.arange(200) / 200
    lemniscate = lambda lift: np.stack([np.sin(t), np.sin(2 * t) / 2, lift * np.cos(t)], axis=1)  # noqa: E731
    with pytest.warns(UserWarning, match=r"writhe 0\.49\d is nearly half-way between two integers: Lk0 = 0 taken"):
        assert jr.closed_curve(lemniscate(0.38), material=MAT).Lk0 == 0.0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert jr.closed_curve(lemniscate(1.0), material=MAT).Lk0 == 0.0  # writhe 0: no doubt
    with pytest.raises(ValueError, match="Lk0 must be an integer"):
        jr.closed_curve(lemniscate(1.0), material=MAT, Lk0=0.5)


def test_cli_lk0_reaches_the_study_and_the_header_says_which(tmp_path, monkeypatch, capsys):
    import jaxrod.studies.twist as study
    from jaxrod.cli import main

    curve = tmp_path / "five.csv"
    np.savetxt(curve, pentagram(), delimiter=",", header="x,y,z", comments="")
    seen = []

    def fake_study(scene, *args, **kwargs):  # the scene the CLI built; stop there
        seen.append(scene)
        raise KeyboardInterrupt

    monkeypatch.setattr(study, "twist_study", fake_study)
    common = ["knot", "--curve", str(curve), "--N", "61", "--no-figures"]
    assert main(common + ["--out", str(tmp_path / "a")]) == 130
    assert main(common + ["--lk0", "0", "--out", str(tmp_path / "b")]) == 130
    assert [s.Lk0 for s in seen] == [-1.0, 0.0]
    err = capsys.readouterr().err
    assert "Lk0 = -1 (the integer nearest the writhe as drawn)" in err and "Lk0 = 0 (given)" in err


def test_one_default_young_modulus_for_the_api_and_the_cli():
    # Issue 16, defect 9: trefoil() defaulted to E = 1 while the CLI used 0.474 MPa.
    import inspect

    from jaxrod import cli
    from jaxrod.model import scenes

    assert cli.PAPER_YOUNG_MODULUS == scenes.PAPER_YOUNG_MODULUS == 0.474
    for factory in (scenes.trefoil, scenes.knot, scenes.torus_knot):
        assert inspect.signature(factory).parameters["E"].default == scenes.PAPER_YOUNG_MODULUS
    parser = cli.build_parser()
    args = parser.parse_args(["trefoil"])
    assert args.E == scenes.PAPER_YOUNG_MODULUS
    assert jr.trefoil(D=8.0, L=292.0, N=61).material.B == pytest.approx(0.474 * math.pi * 8.0**4 / 64)
