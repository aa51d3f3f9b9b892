"""`jaxrod helix` against Neukirch, van der Heijden & Thompson (2002): the formulas' range checked
from the inputs, the mirror symmetry (d, R) -> (d, -R), (m, t) -> (-m, t), the material set by B
and C (any C/B) and the choice between the two loops at given (d, R), and stiff rods (Newton's
tolerance in the rod's own force units, the helical start stiffened in stages).

One rod size, N = 120 (lambda <= 19.6 resolved), so that every solve here shares one set of
compiled programs; the accuracy at N = 400 (Richardson from N = 201 and 400) is
benchmarks/helix_reference.py's."""
import json
import math
import re

from jaxrod.studies import endloads as el
from jaxrod.cli import main
from jaxrod.model.material import Material

N = 120
# (m, t, gamma): lambda = 14.1, 13.9, 16.4 (each the larger-t root at its (d, R), far from the fold)
LOOPS = ((20.0, 300.0, 2.0 / 3.0), (15.0, 250.0, 1.0), (18.0, 350.0, 1.0 / 1.3))
QUIET = ["--quiet", "--no-cache", "--no-extrapolate"]


def _run(capsys, *argv):
    rc = main(["helix", *argv])
    out = capsys.readouterr()
    return rc, out.out, out.err


def test_reference_range_is_checked_from_the_inputs(capsys):
    """(d, R) = (0.03, pi) has lambda = 0.008: the loop is wider than the rod and eqs. 14-15 do not
    describe it. The command says so (text and JSON, no error figure) and --strict refuses it; a
    localized, inextensible case stays valid; a soft rod's stretch is a reason too."""
    (wide,) = el.localized_helix_from_shortening(0.03, math.pi, 2.0 / 3.0)
    assert abs(el.localization_parameter(wide.m, wide.t) - 0.00806) < 1e-5
    check = el.reference_check(wide)
    assert not check.valid and "lambda" in check.reason
    ok = el.localized_helix(20.0, 300.0, 2.0 / 3.0)
    assert el.reference_check(ok, 16.0 / 2e-4 ** 2).valid  # the CLI's default rod, D/L = 2e-4
    soft = el.reference_check(ok, 1e5)  # T/EA = 3e-3: t shifted by ~6 %
    assert not soft.valid and "stretch" in soft.reason and 0.03 < soft.shift < 0.1

    rc, out, _ = _run(capsys, "--d", "0.03", "--R", "1pi", "--N", str(N), "--json", *QUIET)
    assert rc == 0
    res = json.loads(out)
    assert res["reference_valid"] is False and "lambda" in res["reference_reason"]
    assert res["m_rel_error"] is None and res["t_rel_error"] is None and res["envelope_L1"] is None
    assert res["roots"][0]["reference_valid"] is False and res["roots"][0]["t_rel_error"] is None
    rc, out, _ = _run(capsys, "--d", "0.03", "--R", "1pi", "--N", str(N), *QUIET)
    assert rc == 0 and "not applicable: not localized: lambda" in out and "analytic" not in out.split("\n", 1)[1]
    rc, _, err = _run(capsys, "--d", "0.03", "--R", "1pi", "--N", str(N), "--strict", *QUIET)
    err = err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and "--strict" in err[0] and "lambda" in err[0], err


def test_mirror_image_has_opposite_moment_and_the_same_tension():
    """(x, y, z) -> (x, -y, z) maps the loop with end rotation R and moment M onto one with -R and
    -M at the same tension: in the formulas (both directions) and in the discrete solve, exactly
    (to Newton's tolerance), at three (d, R)."""
    for m, t, gamma in LOOPS:
        ref, mirror = el.localized_helix(m, t, gamma), el.localized_helix(-m, t, gamma)
        assert abs(mirror.R + ref.R) < 1e-12 * ref.R and abs(mirror.Wr + ref.Wr) < 1e-12
        assert mirror.d == ref.d and mirror.theta_max == ref.theta_max and mirror.Tw == -ref.Tw
        plus = el.localized_helix_from_shortening(ref.d, ref.R, gamma)
        minus = el.localized_helix_from_shortening(ref.d, -ref.R, gamma)
        assert len(plus) == len(minus) >= 1
        assert any(abs(h.m + m) < 1e-9 * m and abs(h.t / t - 1.0) < 1e-9 for h in minus), minus
        for a, b in zip(plus, minus):
            assert abs(a.m + b.m) < 1e-12 * abs(a.m) and a.t == b.t and abs(a.R + b.R) < 1e-9
    for m, t, gamma in LOOPS:
        ref = el.localized_helix(m, t, gamma)
        rod = el.shortened_rod(N, 1.0, Material.from_ratio(B=1.0, nu=1.0 / gamma - 1.0, D=2e-4), shortening=ref.d)
        got = []
        for sign in (1.0, -1.0):
            e = el.solve_from_helix(rod, sign * m, t, sign * ref.R, el.EndLoadOptions(k=4))
            loads = el.end_loads(rod, e.q, sign * ref.R, e.neighbourhood)
            got.append((loads.M, loads.T, e.stability.n_negative, e.Lk))
        (M1, T1, k1, lk1), (M2, T2, k2, lk2) = got
        assert abs(M1 + M2) < 1e-7 * abs(M1) and abs(T1 - T2) < 1e-7 * T1, got
        assert k1 == k2 and abs(lk1 + lk2) < 1e-10
        assert abs(M1 / m - 1.0) < 0.02 and abs(T1 / t - 1.0) < 0.1  # N = 120: the O(h^2) error


def test_material_set_directly_and_the_root_chosen(capsys):
    """C/B = 0.5 (nu = 1: outside (-1, 0.5]) set by --B and --C, at a negative end rotation: both
    analytic loops at (d, R) are solved, each with its Morse index; the stable one is taken and
    named. The loads scale with B; m, t near the valid root's analytic values at N = 120."""
    ref = el.localized_helix(20.0, 300.0, 0.5)
    ends = ["--d", repr(ref.d), f"--R={-ref.R!r}", "--N", str(N)]
    rc, out, _ = _run(capsys, *ends, "--B", "2", "--C", "1", "--json", *QUIET)
    assert rc == 0
    res = json.loads(out)
    assert res["B"] == 2.0 and res["C"] == 1.0 and res["gamma"] == 0.5
    roots = {r["root"]: r for r in res["roots"]}
    assert sorted(roots) == ["large", "small"] and all(isinstance(r["morse"], int) for r in roots.values())
    assert abs(roots["large"]["t_analytic"] / 300.0 - 1.0) < 1e-9 and roots["large"]["reference_valid"]
    assert not roots["small"]["reference_valid"]  # lambda = 8.0
    stable = [k for k, r in roots.items() if r["morse"] == 0]
    assert res["root"] == (stable[0] if len(stable) == 1 else "large") and res["root_reason"]
    assert abs(res["M"] - 2.0 * res["m"]) < 1e-12 * abs(res["M"]) and abs(res["T"] - 2.0 * res["t"]) < 1e-9 * res["T"]
    assert roots["large"]["m"] < 0.0 and abs(roots["large"]["m_rel_error"]) < 0.02
    assert abs(roots["large"]["t_rel_error"]) < 0.1
    # one root asked for: only it is solved; --gamma is the same material
    rc, out, _ = _run(capsys, *ends, "--gamma", "0.5", "--B", "2", "--root", "large", "--json", *QUIET)
    res2 = json.loads(out)
    assert rc == 0 and res2["root"] == "large" and len(res2["roots"]) == 1
    assert abs(res2["m"] / roots["large"]["m"] - 1.0) < 1e-7 and abs(res2["t"] / roots["large"]["t"] - 1.0) < 1e-7
    for argv, flag in ((["--nu", "0.3", "--C", "1"], "give one of --nu, --gamma and --C"),
                       (["--C", "-1"], "--C must be positive"),
                       (["--B", "0"], "--B must be positive")):
        rc, _, err = _run(capsys, *ends, *argv, *QUIET)
        err = err.strip().splitlines()
        assert rc == 2 and len(err) == 1 and re.search(flag, err[0]), err
    rc, _, err = _run(capsys, "--m", "20", "--t", "300", "--root", "small", *QUIET)
    assert rc == 2 and "--root" in err


def test_stiff_rods_converge_to_the_same_relative_accuracy(capsys):
    """B = 1e-3 and EA = 1e3 ... 1e9 (EA L^2/B = 1e6 ... 1e12): each converges to Newton's tolerance
    in force units (``gradient_tolerance``), and t = TL^2/B moves with EA only by the stretch's
    shift (``stretch_shift``) or at the stiffest by the roundoff of EA times a strain. The CLI's
    D/L = 1e-5 (EA L^2/B = 1.6e11) solves and gives the t of D/L = 2e-4."""
    # (N = 120 is too coarse for the extrapolation's N = 61: none)
    rc, out, err = _run(capsys, "--m", "20", "--t", "300", "--N", str(N), "--slenderness", "1e-5", "--json",
                        "--quiet", "--no-cache")
    assert rc == 0, err
    res = json.loads(out)
    m, t, gamma = LOOPS[0]
    ref = el.localized_helix(m, t, gamma)
    B, got = 1e-3, {}
    for EA in (1e3, 1e5, 1e7, 1e9):
        rod = el.shortened_rod(N, 1.0, Material(B=B, C=gamma * B, EA=EA), shortening=ref.d)
        tol = el.gradient_tolerance(rod)
        h = 1.0 / (N - 2)
        force = tol * B / h ** 2  # the residual force allowed per node
        assert 1e-6 * B <= force <= 1e-6 * B + 5e-13 * EA
        e = el.solve_from_helix(rod, m, t, ref.R, el.EndLoadOptions(with_stability=False))
        assert e.solution.converged and e.solution.grad_norm <= tol
        loads = el.end_loads(rod, e.q, ref.R, e.neighbourhood)
        got[EA] = (loads.M / B, loads.T / B)
    t_stiff = got[1e7][1]
    for EA, (m_, t_) in got.items():
        shift = el.stretch_shift(ref, EA / B)
        assert abs(t_ / t_stiff - 1.0) < 1.5 * shift + 3e-4, (EA, t_, t_stiff, shift)
        assert abs(m_ / got[1e7][0] - 1.0) < 1e-3
    assert res["reference_valid"] and abs(res["t"] / t_stiff - 1.0) < 3e-4 and res["morse"] == 1


def test_failed_solve_advises_for_the_helix(capsys, monkeypatch):
    """No equilibrium: one line on stderr, exit 1, advice about this command's flags (no knot)."""
    from jaxrod.solve.solvers import ConvergenceError

    def fail(*args, **kwargs):
        raise ConvergenceError("capped Newton did not converge")

    monkeypatch.setattr(el, "solve", fail)
    monkeypatch.setattr(el, "solve_from_helix", fail, raising=False)
    rc, _, err = _run(capsys, "--m", "20", "--t", "300", "--N", str(N), "--quiet", "--no-cache")
    err = err.strip().splitlines()
    assert rc == 1 and len(err) == 1 and "--N" in err[0] and "knot" not in err[0], err


def test_sweep_range_in_help_and_readme(capsys):
    """--sweep K spans 0.8 R ... 1.1 R: the help, the command's description and the README agree."""
    from pathlib import Path

    assert main(["helix", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "from 0.8 R to 1.1 R" in text and "0.9 R" not in text
    readme = " ".join((Path(__file__).parent.parent / "docs" / "guides" / "end-loads.md").read_text().split())
    assert "from 0.8 R to 1.1 R" in readme
