"""Analysis of rod data (jaxrod.measure.analysis): frames, kappa1/kappa2/tau profiles, Wr, Tw, Lk from a
centreline and an eccentric line, as in the seed paper; file input and profile output."""
import math

import jax.numpy as jnp
import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from jaxrod import Material, closed_curve
from jaxrod.measure.analysis import RodAnalysis, analyze, load_polyline, write_profiles_csv
from jaxrod.model.energy import vertex_curvature_binormals
from jaxrod.model.geometry import node_directors
from helpers import trefoil_points

TWO_PI = 2 * math.pi


# ---------------------------------------------------------------------------- 1. analytic circle
def _circle_ribbon(R, k, n_centre, n_ecc, offset, phase=0.3):
    """Circle of radius R in a tilted plane, and an eccentric line turning k times right-handedly:
    d1 = cos(psi) u + sin(psi) v, u radial outwards, v = t x u, psi = 2 pi k s / L.
    The eccentric line is sampled at other points than the centreline (shifted, other count)."""
    L = TWO_PI * R
    rot = np.linalg.qr(np.random.default_rng(3).normal(size=(3, 3)))[0]

    def frame(s):
        a = s / R
        u = np.stack([np.cos(a), np.sin(a), 0 * a], 1)
        t = np.stack([-np.sin(a), np.cos(a), 0 * a], 1)
        return R * u @ rot.T, u @ rot.T, np.cross(t, u) @ rot.T

    x, _, _ = frame(L * np.arange(n_centre) / n_centre)
    s2 = L * (np.arange(n_ecc) + phase) / n_ecc
    x2, u2, v2 = frame(s2)
    psi = TWO_PI * k * s2 / L
    ecc = x2 + offset * (np.cos(psi)[:, None] * u2 + np.sin(psi)[:, None] * v2)
    return x, ecc, rot


@pytest.mark.parametrize("k", [3, -2])
def test_circle_with_uniformly_turning_eccentric_line(k):
    R, n = 1.3, 256
    x, ecc, rot = _circle_ribbon(R, k, n, 199, offset=0.05 * R)
    res = analyze(x, ecc)
    L = TWO_PI * R
    assert isinstance(res, RodAnalysis)
    assert np.all(res.paired)
    assert res.length == pytest.approx(L, rel=1e-8)  # spline interpolant: O(h^4) = 5e-10
    # Exact topological numbers: a planar polygon has writhe 0; the frame sums to an integer.
    assert res.Wr == pytest.approx(0.0, abs=1e-12)
    assert res.Tw == pytest.approx(k, abs=1e-10)
    assert res.Lk_exact == pytest.approx(k, abs=1e-10)
    assert res.Lk_frames == pytest.approx(k, abs=1e-10)
    # Second-order quantities, h = L/256: compact second difference, error (h/R)^2/12 = 5e-5
    # relative; d1' by central differences of a vector turning at rate w = sqrt(kappa^2 + tau^2),
    # error (w h)^2/6 = 1e-3 (k = 3) relative. Midpoint Gauss quadrature: O(h^2) too.
    assert np.max(np.abs(res.kappa * R - 1.0)) < 2e-4
    tau0 = TWO_PI * k / L
    assert np.max(np.abs(res.tau / tau0 - 1.0)) < 3e-3
    assert res.Tw_integral == pytest.approx(k, abs=3e-3 * abs(k))
    assert res.Lk_quadrature == pytest.approx(k, abs=0.02)
    # Signs. On the circle d3' = -u/R and (u, v, d3) is parallel transported (u' = d3/R, v' = 0),
    # so d1 = cos(psi) u + sin(psi) v, d2 = d3 x d1 = cos(psi) v - sin(psi) u and
    #   kappa2 = d3'.d1 = -cos(psi)/R,  kappa1 = d2'.d3 = -d2.d3' = u.d2/R = -sin(psi)/R,
    #   tau = d1'.d2 = psi' = 2 pi k / L.
    # (Equivalently kappa1 d1 + kappa2 d2 = d3 x d3' = -v/R, the curvature binormal.)
    psi = TWO_PI * k * res.s / L
    assert np.max(np.abs(res.kappa1 + np.sin(psi) / R)) < 2e-4 / R
    assert np.max(np.abs(res.kappa2 + np.cos(psi) / R)) < 2e-4 / R
    binormal = res.kappa1[:, None] * res.d1 + res.kappa2[:, None] * res.d2
    v = np.cross(res.d3, res.x / R)  # t x u
    assert np.max(np.abs(binormal + v / R)) < 2e-4 / R
    # The frame is orthonormal and right-handed.
    for a, b in ((res.d1, res.d2), (res.d2, res.d3), (res.d3, res.d1)):
        assert np.max(np.abs(np.sum(a * b, axis=1))) < 1e-12
    assert np.allclose(np.cross(res.d1, res.d2), res.d3, atol=1e-12)
    # The eccentric line given in the opposite direction, or with a repeated closing point:
    # same results (it is oriented along the centreline before computing Lk).
    rev = analyze(np.vstack([x, x[:1]]), ecc[::-1])
    assert rev.Lk_exact == pytest.approx(k, abs=1e-10)
    assert np.allclose(rev.tau, res.tau, atol=1e-8) and np.allclose(rev.kappa1, res.kappa1, atol=1e-8)


# ---------------------------------------------------------------------------- 2. jaxrod's own rod
def _twisted_trefoil(n, turns=3, modulation=0.5):
    """Closed rod on a right-handed trefoil (helpers' trefoil mirrored, so Lk0 = +3) with twist
    phi = 2 pi turns spread uniformly (as tests/test_conventions.py) plus a smooth non-uniform part
    (mode 2), so that tau(s) is not constant. The curve is resampled from a 16x finer polygon so that
    the rod's nodes lie on a smooth curve to O((h/16)^2) (a linear resampling of a coarse polygon
    would put O(h^2 kappa) kinks into it, i.e. O(1) noise into second differences)."""
    pts = trefoil_points(16 * n) * np.array([1.0, 1.0, -1.0])
    scene = closed_curve(pts, material=Material(B=1, C=1 / 1.5, EA=100), N=n)
    phi = TWO_PI * turns
    q = np.asarray(scene.q_init).copy()
    i = np.arange(n)
    q[3 * n:] += phi * i / n + modulation * np.sin(4 * np.pi * i / n)
    return scene, jnp.asarray(q), phi


def _rod_reference(scene, q, phi):
    """The rod's own profiles at its vertices (= nodes for a closed rod: vertex i joins edges i-1 and
    i at node i): kappa = |kb|/l, kappa1 = kb.d1/l, kappa2 = kb.d2/l with the node directors (kb is
    the curvature binormal kappa b h = (kappa1 d1 + kappa2 d2) h), tau = m/l, and Wr, Tw, Lk."""
    x, _ = scene.unpack(q, phi)
    vor = np.asarray(scene.voronoi)
    kb = np.asarray(vertex_curvature_binormals(x, True))
    d1e, _, _ = scene.material_frames(q, phi)
    d1 = np.asarray(node_directors(x, d1e, True))
    return dict(
        x=np.asarray(x),
        kappa=np.linalg.norm(kb, axis=1) / vor,
        kb=kb / vor[:, None],
        d1=d1,
        tau=np.asarray(scene.vertex_twists(q, phi)) / vor,
        Wr=float(scene.writhe(q, phi)),
        Tw=float(scene.twist(q, phi)),
        Lk=float(scene.linking_number(q, phi)),
        L=float(scene.length),
    )


def test_round_trip_with_jaxrod_closed_rod():
    errors = {}
    for n in (150, 300):
        scene, q, phi = _twisted_trefoil(n)
        ref = _rod_reference(scene, q, phi)
        ecc = np.asarray(scene.eccentric_line(q, phi, offset=0.01 * ref["L"]))
        res = analyze(ref["x"], ecc)
        # Lk = Lk0 + phi/2pi = 3 + 3; the analysis sees the same polygon (its nodes move by
        # < 1e-6 L in the arc-length resampling of the spline through them), so Wr agrees to
        # ~1e-9 and Tw = Lk - Wr exactly as well.
        assert ref["Lk"] == pytest.approx(6.0, abs=1e-8)
        assert np.max(np.linalg.norm(res.x - ref["x"], axis=1)) < 1e-6 * ref["L"]
        assert res.Lk_exact == pytest.approx(ref["Lk"], abs=1e-8)
        assert res.Lk_frames == pytest.approx(ref["Lk"], abs=1e-8)
        assert res.Wr == pytest.approx(ref["Wr"], abs=1e-8)
        assert res.Tw == pytest.approx(ref["Tw"], abs=1e-8)
        # d1 is recovered from the eccentric line (the paired point is the line's own node: the
        # node director is normal to the bisector tangent, which is our central-difference tangent).
        cos = np.clip(np.sum(res.d1 * ref["d1"], axis=1), -1, 1)
        assert np.max(np.arccos(cos)) < 1e-4
        k1 = np.sum(ref["kb"] * ref["d1"], axis=1)
        k2 = np.sum(ref["kb"] * np.cross(res.d3, ref["d1"]), axis=1)
        kmax, tmax = ref["kappa"].max(), np.abs(ref["tau"]).max()
        errors[n] = dict(
            kappa=np.max(np.abs(res.kappa - ref["kappa"])) / kmax,
            k12=max(np.max(np.abs(res.kappa1 - k1)), np.max(np.abs(res.kappa2 - k2))) / kmax,
            tau=np.max(np.abs(res.tau - ref["tau"])) / tmax,
            Tw_integral=abs(res.Tw_integral - ref["Tw"]),
            Lk_quadrature=abs(res.Lk_quadrature - ref["Lk"]),
        )
    # Both sides are second-order approximations of the same smooth rod: the rod's 2 tan(a/2)/h
    # and our compact second difference both err by ~(h kappa)^2/12 (h = L/300 = 0.096,
    # kappa <= 0.78: 5e-4); tau: our central difference of d1 (turning at w ~ 1.1, (w h)^2/6 = 2e-3)
    # against m/l, while our node directors average the edge angles, so we see
    # (m_{i-1} + 2 m_i + m_{i+1})/4 = m_i + O(h^2) (another ~1e-3). Measured at N = 300:
    # kappa 1.0e-3, tau 3.3e-3, Tw_integral 3.3e-3, Lk_quadrature 2.9e-3; each about 4x smaller
    # than at N = 150 (second order).
    e150, e300 = errors[150], errors[300]
    assert e300["kappa"] < 3e-3 and e300["k12"] < 3e-3
    assert e300["tau"] < 1e-2
    assert e300["Tw_integral"] < 1e-2
    assert e300["Lk_quadrature"] < 1e-2
    for key in e300:
        assert e150[key] / e300[key] > 3.0, (key, e150[key], e300[key])


# ---------------------------------------------------------------------------- 3. noisy data
def test_noisy_non_matching_samples_with_smoothing():
    n = 360
    scene, q, phi = _twisted_trefoil(n)
    ref = _rod_reference(scene, q, phi)
    L = ref["L"]
    offset = 0.01 * L
    ecc = np.asarray(scene.eccentric_line(q, phi, offset=offset))
    # The eccentric line at 290 points of a shifted parameter (spline through the rod's line).
    s_nodes = L * np.arange(n + 1) / n
    spline = CubicSpline(s_nodes, np.vstack([ecc, ecc[:1]]), bc_type="periodic")
    n_ecc = 290
    ecc_data = spline(L * (np.arange(n_ecc) + 0.37) / n_ecc)
    rng = np.random.default_rng(0)
    sigma = 1e-3 * L
    x_data = ref["x"] + sigma * rng.normal(size=(n, 3))
    ecc_data = ecc_data + sigma * rng.normal(size=(n_ecc, 3))
    K = 12
    res = analyze(x_data, ecc_data, n_samples=300, smoothing_modes=K)
    # Topology: exact integers, unharmed by noise (sigma is 10x smaller than the offset).
    assert res.Lk_exact == pytest.approx(6.0, abs=1e-8)
    assert res.Lk_frames == pytest.approx(res.Lk_exact, abs=1e-8)
    # Wr, Tw are integrals over the smoothed shape: residual noise ~ sigma sqrt((2K+1)/n) ~ 3e-4 L,
    # a per-mille of the shape; measured |dWr| = |dTw| = 1.8e-3, Tw_integral 5e-3, quadrature 3e-3.
    assert res.Wr == pytest.approx(ref["Wr"], abs=0.01)
    assert res.Tw == pytest.approx(ref["Tw"], abs=0.01)
    assert res.Tw_integral == pytest.approx(ref["Tw"], abs=0.02)
    assert res.Lk_quadrature == pytest.approx(6.0, abs=0.02)
    assert res.length == pytest.approx(L, rel=5e-3)
    # Profiles against the rod's, at the same fraction of the length (s = 0 at the first
    # centreline point in both).
    s_ref = L * np.arange(n) / n
    s_res = res.s / res.length * L
    kappa_ref = np.interp(s_res, s_ref, ref["kappa"], period=L)
    tau_ref = np.interp(s_res, s_ref, ref["tau"], period=L)
    rms = lambda a: float(np.sqrt(np.mean(a**2)))  # noqa: E731
    err_kappa = rms(res.kappa - kappa_ref) / rms(kappa_ref)
    err_tau = rms(res.tau - tau_ref) / rms(tau_ref)
    # Expected noise after the low-pass (white noise keeps a fraction (2K+1)/n of its variance;
    # a mode k is amplified by (2 pi k/L)^p by the p-th derivative, RMS over k <= K:
    # K^p/sqrt(2p+1)):
    #   kappa: sqrt(2) sigma sqrt(25/360) (2 pi/L)^2 K^2/sqrt(5) = 0.033, 6% of rms(kappa) = 0.54;
    #   tau: the angle of d1 sees the noise of both curves over the offset,
    #        sqrt(25/360 + 25/290) sigma/offset (2 pi/L) K/sqrt(3) = 0.060, 10% of rms(tau) = 0.58,
    # plus the truncation bias of K = 12 (measured without noise: 1.6% and 2.3%).
    # Measured (seeds 0-3): kappa 3.6-5.4%, tau 11-13%. Bounds: about 2x the estimate.
    assert err_kappa < 0.12, err_kappa
    assert err_tau < 0.22, err_tau
    # Without smoothing the same data gives useless profiles (differentiating raw noise), and
    # analyze says so: the noise makes the pairing jump back and forth along the line.
    with pytest.warns(UserWarning, match="pairing jumps"):
        raw = analyze(x_data, ecc_data, n_samples=300)
    assert rms(raw.kappa - kappa_ref) / rms(kappa_ref) > 1.0
    assert res.warnings == ()  # the smoothed analysis of the same data is trusted


# ---------------------------------------------------------------------------- open curves
def _helix(phi, rho, c):
    return np.stack([rho * np.cos(phi), rho * np.sin(phi), c * phi], axis=1)


@pytest.mark.parametrize("noisy", [False, True])
def test_open_helix_frenet_ribbon(noisy):
    # Right-handed helix; eccentric line along the principal normal N = -(cos, sin, 0), so
    # d1 = N, d2 = B: kappa1 = B'.T = 0, kappa2 = T'.N = kappa, tau = N'.B = Frenet torsion.
    rho, c, a = 1.0, 0.6, 0.1
    speed = math.hypot(rho, c)
    kappa0, tau0 = rho / speed**2, c / speed**2
    phi = np.linspace(0.0, 4 * np.pi, 241)
    x = _helix(phi, rho, c)
    phi_e = np.linspace(-0.2, 4 * np.pi + 0.2, 173)  # other points, covering the ends
    ecc = _helix(phi_e, rho, c) - a * np.stack([np.cos(phi_e), np.sin(phi_e), 0 * phi_e], axis=1)
    L = 4 * np.pi * speed
    if noisy:
        rng = np.random.default_rng(1)
        sigma = 2e-4 * L
        x = x + sigma * rng.normal(size=x.shape)
        ecc = ecc + sigma * rng.normal(size=ecc.shape)
    res = analyze(x, ecc, closed=False, n_samples=200, smoothing_modes=16 if noisy else None)
    assert res.s[0] == 0.0 and res.s[-1] == pytest.approx(res.length)
    assert math.isnan(res.Lk_exact) and math.isnan(res.Lk_quadrature)
    assert res.Lk_frames == pytest.approx(res.Wr + res.Tw)
    assert res.Wr > 0  # right-handed
    assert np.all(res.paired)  # every normal plane crosses the (longer) eccentric line
    Tw0 = tau0 * L / TWO_PI
    kerr, terr = res.kappa / kappa0 - 1, res.tau / tau0 - 1
    if not noisy:
        # Second order: interior stencils err by ~(h kappa)^2/12 = 3e-4 (h = L/199); the one-sided
        # second difference at the ends has an 11x larger constant (11/12 h^2 x^(4)).
        assert res.length == pytest.approx(L, rel=1e-8)
        interior = slice(1, -1)
        assert np.max(np.abs(kerr[interior])) < 1e-3 and np.max(np.abs(kerr)) < 6e-3
        assert np.max(np.abs(terr[interior])) < 1e-3 and np.max(np.abs(terr)) < 6e-3
        assert np.max(np.abs(res.kappa1)) < 1e-3 * kappa0
        assert res.Tw == pytest.approx(Tw0, rel=1e-3)
        assert res.Tw_integral == pytest.approx(Tw0, rel=1e-3)
    else:
        # Regression spline with 16 intervals (~8 per turn): measured (seeds 1-3) RMS errors
        # kappa 2.7-3.1%, tau 5.8-6.9% (tau carries the noise of both curves over the small offset
        # a = 0.1: sigma/a = 0.026 rad per point), Tw 0.2-0.6%; the ends are the noisiest part.
        rms = lambda v: float(np.sqrt(np.mean(v**2)))  # noqa: E731
        assert res.length == pytest.approx(L, rel=2e-3)
        assert rms(kerr) < 0.08 and rms(terr) < 0.15
        assert rms(res.kappa1) < 0.1 * kappa0
        assert res.Tw == pytest.approx(Tw0, rel=0.02)
        assert res.Tw_integral == pytest.approx(Tw0, rel=0.02)


# ---------------------------------------------------------------------------- analyze validation
def test_open_eccentric_line_shorter_than_centreline_is_flagged():
    phi = np.linspace(0.0, 4 * np.pi, 101)
    x = _helix(phi, 1.0, 0.5)
    phi_e = np.linspace(0.5, 4 * np.pi - 0.5, 80)
    ecc = _helix(phi_e, 1.0, 0.5) * np.array([1.1, 1.1, 1.0])
    with pytest.warns(UserWarning, match="normal plane misses the eccentric line"):
        res = analyze(x, ecc, closed=False)
    # Nodes whose normal plane misses the line (within ~0.5 rad of either end) fall back to the
    # nearest point and are flagged; the others are paired normally.
    assert not res.paired[0] and not res.paired[-1]
    assert np.all(res.paired[10:-10])
    assert np.all(np.isfinite(res.tau))


def test_analyze_rejects_bad_arrays():
    x, ecc, _ = _circle_ribbon(1.0, 1, 32, 32, offset=0.1)
    with pytest.raises(ValueError, match=r"centreline.*shape"):
        analyze(x[:, :2], ecc)
    with pytest.raises(ValueError, match=r"eccentric.*shape"):
        analyze(x, ecc.ravel())
    bad = x.copy()
    bad[5, 1] = np.nan
    with pytest.raises(ValueError, match=r"centreline.*non-finite.*rows 5"):
        analyze(bad, ecc)
    with pytest.raises(ValueError, match=r"eccentric.*at least 4"):
        analyze(x, ecc[:3])
    with pytest.raises(ValueError, match=r"lies on the centreline"):
        analyze(x, x)
    with pytest.raises(ValueError, match=r"^smoothing_modes"):
        analyze(x, ecc, smoothing_modes=40)
    with pytest.raises(ValueError, match=r"^n_samples"):
        analyze(x, ecc, n_samples=3)
    with pytest.raises(ValueError, match=r"^n_samples"):
        analyze(x, ecc, n_samples="many")
    with pytest.raises(ValueError, match=r"^smoothing_modes"):
        analyze(x, ecc, smoothing_modes=2.5)
    with pytest.raises(ValueError, match=r"^closed"):
        analyze(x, ecc, closed="yes")


# ---------------------------------------------------------------------------- 4. bad files
def _write(path, text):
    path.write_text(text)
    return path


BAD_CSV = {
    "missing_z.csv": ("x,y,w\n" + "1,2,3\n" * 5, r"missing column\(s\) z"),
    "no_columns.csv": ("a,b,c,d\n" + "1,2,3,4\n" * 5, r"missing column\(s\) x, y, z"),
    "nan.csv": ("x,y,z\n" + "0,0,0\n1,0,0\n1,1,nan\n0,1,0\n0,2,0\n", r"non-finite .* rows 2"),
    "inf.csv": ("0,0,0\n1,0,0\n1,1,inf\n0,1,0\n", r"non-finite"),
    "three_points.csv": ("x,y,z\n0,0,0\n1,0,0\n1,1,0\n", r"at least 4 points"),
    "two_columns.csv": ("0,0\n1,0\n1,1\n0,1\n", r"exactly 3 numeric columns"),
    "ragged.csv": ("x,y,z\n0,0,0\n1,0\n1,1,0\n0,1,0\n", r"line 3 has 2 columns"),
    "text_value.csv": ("y,x,z\n0,0,0\n1,0,0\n1,one,0\n0,1,0\n", r"line 4: value 'one' is not a number"),
    "empty.csv": ("\n\n", r"empty"),
}


@pytest.mark.parametrize("name", sorted(BAD_CSV))
def test_bad_csv_files(tmp_path, name):
    text, problem = BAD_CSV[name]
    path = _write(tmp_path / name, text)
    with pytest.raises(ValueError, match=problem) as info:
        load_polyline(path)
    assert str(path) in str(info.value)


@pytest.mark.parametrize(
    "array, problem",
    [
        (np.zeros((10, 2)), r"shape \(N, 3\), got shape \(10, 2\)"),
        (np.zeros((10, 3, 1)), r"shape \(N, 3\)"),
        (np.zeros(12), r"shape \(N, 3\)"),
        (np.zeros((3, 3)), r"at least 4 points"),
        (np.array([[0, 0, 0], [1, 0, 0], [1, 1, np.inf], [0, 1, 0]], dtype=float), r"non-finite"),
        (np.array([["a", "b", "c"]] * 4), r"not numeric"),
    ],
)
def test_bad_npy_files(tmp_path, array, problem):
    path = tmp_path / "bad.npy"
    np.save(path, array)
    with pytest.raises(ValueError, match=problem) as info:
        load_polyline(path)
    assert str(path) in str(info.value)


def test_unknown_extension_and_object_npy(tmp_path):
    path = _write(tmp_path / "points.txt", "0,0,0\n1,0,0\n1,1,0\n0,1,0\n")
    with pytest.raises(ValueError, match=r"points\.txt: unknown file extension '\.txt'"):
        load_polyline(path)
    obj = tmp_path / "obj.npy"
    np.save(obj, np.array([{"x": 1}] * 4, dtype=object), allow_pickle=True)
    with pytest.raises(ValueError, match=r"obj\.npy"):
        load_polyline(obj)


# ---------------------------------------------------------------------------- 5. good files
def test_read_csv_any_column_order_extra_columns_and_npy(tmp_path):
    pts = np.random.default_rng(4).normal(size=(7, 3))
    lines = ["# exported skeleton", "id, Z ,label,x,y,radius"]
    for i, (x, y, z) in enumerate(pts):
        lines.append(f"{i},{z:.17g},node{i},{x:.17g},{y:.17g},0.5")
        if i == 2:
            lines.append("")  # blank lines are skipped
    path = _write(tmp_path / "skeleton.csv", "\n".join(lines) + "\n")
    assert np.array_equal(load_polyline(path), pts)
    bare = _write(tmp_path / "bare.csv", "".join(f"{x:.17g}, {y:.17g}, {z:.17g}\n" for x, y, z in pts))
    assert np.array_equal(load_polyline(bare), pts)
    npy = tmp_path / "pts.npy"
    np.save(npy, pts.astype(np.float32))
    loaded = load_polyline(npy)
    assert loaded.dtype == np.float64 and np.allclose(loaded, pts, rtol=1e-6)
    np.save(npy, np.arange(12).reshape(4, 3))  # integer arrays are fine
    assert np.array_equal(load_polyline(npy), np.arange(12.0).reshape(4, 3))


def test_files_to_profiles_csv(tmp_path):
    x, ecc, _ = _circle_ribbon(1.0, 2, 64, 50, offset=0.05)
    np.save(tmp_path / "centre.npy", x)
    with open(tmp_path / "ecc.csv", "w") as fh:
        fh.write("z,y,x\n" + "".join(f"{p[2]:.17g},{p[1]:.17g},{p[0]:.17g}\n" for p in ecc))
    res = analyze(load_polyline(tmp_path / "centre.npy"), load_polyline(tmp_path / "ecc.csv"))
    direct = analyze(x, ecc)
    assert np.array_equal(res.tau, direct.tau) and res.Lk_exact == direct.Lk_exact
    out = tmp_path / "profiles.csv"
    write_profiles_csv(res, out)
    lines = out.read_text().splitlines()
    assert lines[0] == "s,kappa1,kappa2,tau,kappa" and len(lines) == 65
    table = np.loadtxt(out, delimiter=",", skiprows=1)
    expected = np.stack([res.s, res.kappa1, res.kappa2, res.tau, res.kappa], axis=1)
    assert np.array_equal(table, expected)  # 17 significant digits: exact round trip
    with pytest.raises(TypeError):
        write_profiles_csv({"s": 1}, out)
    assert not res.tau.flags.writeable  # the result is frozen, arrays included


# ---------------------------------------------------------------------------- 6. profile descriptors
def _profile(n=240, L=2.0, phase=0.4):
    s = L * np.arange(n) / n
    return s, L, phase


def test_symmetry_order_and_peaks_of_a_threefold_profile():
    from jaxrod.measure.analysis import count_peaks, symmetry_order

    s, L, ph = _profile()
    k = 1 + 0.5 * np.cos(3 * TWO_PI * s / L + ph)
    assert symmetry_order(k) == 3 and count_peaks(k) == 3
    # A weaker 1st and 5th harmonic and noise do not change the dominant order or the count.
    rng = np.random.default_rng(7)
    noisy = (k + 0.15 * np.cos(TWO_PI * s / L) + 0.1 * np.sin(5 * TWO_PI * s / L + 1.0)
             + 0.01 * rng.normal(size=s.size))
    assert symmetry_order(noisy) == 3
    assert count_peaks(noisy) == 3
    # Rotating the sampling (a peak across the wrap) counts each peak once.
    for shift in (0, 1, 17, 40, 80):
        assert count_peaks(np.roll(k, shift)) == 3
    # Lists are accepted; max_order below the true order picks the largest allowed harmonic.
    assert symmetry_order(list(k)) == 3
    assert symmetry_order(k + 0.05 * np.cos(TWO_PI * s / L), max_order=2) == 1


def test_symmetry_order_and_peaks_of_bumps():
    from jaxrod.measure.analysis import count_peaks, symmetry_order

    s, L, _ = _profile(n=400)

    def bumps(m, width=0.05, heights=None):
        centres = (np.arange(m) + 0.3) / m
        heights = np.ones(m) if heights is None else np.asarray(heights)
        d = (s[:, None] / L - centres[None, :] + 0.5) % 1.0 - 0.5  # periodic distance
        return 0.2 + np.sum(heights * np.exp(-0.5 * (d / width) ** 2), axis=1)

    k4 = bumps(4)
    assert symmetry_order(k4) == 4 and count_peaks(k4) == 4
    k2 = bumps(2, width=0.08, heights=[1.0, 0.8])  # unequal bumps: still 2-fold dominant
    assert symmetry_order(k2) == 2 and count_peaks(k2) == 2
    # A small side bump is not counted at the default prominence, but is at a lower one.
    side = bumps(4) + 0.05 * np.exp(-0.5 * (((s / L - 0.2 + 0.5) % 1 - 0.5) / 0.01) ** 2)
    assert count_peaks(side) == 4
    assert count_peaks(side, prominence=0.01) == 5
    # A constant profile has no dominant harmonic and no peak.
    assert symmetry_order(np.full(16, 0.3)) == 0 and count_peaks(np.full(16, 0.3)) == 0


@pytest.mark.parametrize(
    "bad, problem",
    [
        (np.ones((8, 2)), r"^kappa: must be a 1-D array"),
        (np.ones(7), r"^kappa: at least 8 samples"),
        (np.r_[np.ones(9), np.nan], r"^kappa: non-finite .* 9"),
        (np.r_[np.ones(9), np.inf], r"^kappa: non-finite"),
        (["a"] * 10, r"^kappa: could not be read"),
    ],
)
def test_profile_descriptors_reject_bad_input(bad, problem):
    from jaxrod.measure.analysis import count_peaks, symmetry_order

    with pytest.raises(ValueError, match=problem):
        symmetry_order(bad)
    with pytest.raises(ValueError, match=problem):
        count_peaks(bad)


def test_profile_descriptors_reject_bad_parameters():
    from jaxrod.measure.analysis import count_peaks, symmetry_order

    k = 1 + np.cos(3 * TWO_PI * np.arange(32) / 32)
    for bad in (0, -1, 2.5, "3", True, None):
        with pytest.raises(ValueError, match=r"^max_order"):
            symmetry_order(k, max_order=bad)
    for bad in (-0.1, float("nan"), "x", None):
        with pytest.raises(ValueError, match=r"^prominence"):
            count_peaks(k, prominence=bad)


def _frenet_offset(x, offset):
    """Eccentric line of a closed polyline: x + offset * the unit Frenet normal (from periodic central
    differences; the curve must have no inflection)."""
    t = np.roll(x, -1, axis=0) - np.roll(x, 1, axis=0)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    a = np.roll(x, -1, axis=0) - 2 * x + np.roll(x, 1, axis=0)
    nrm = a - np.sum(a * t, axis=1, keepdims=True) * t
    return x + offset * nrm / np.linalg.norm(nrm, axis=1, keepdims=True)


def test_trefoil_curvature_is_threefold():
    from jaxrod.measure.analysis import count_peaks, symmetry_order
    from jaxrod.model.scenes import trefoil_points

    x = trefoil_points(240)
    res = analyze(x, _frenet_offset(x, 0.1))
    assert res.Lk_frames == pytest.approx(res.Lk_exact, abs=1e-8)
    assert symmetry_order(res.kappa) == 3
    # This parametrisation's curvature has two equal maxima per lobe (kappa = 0.776 at each, a dip
    # of 0.506 between them, minimum 0.206 between lobes): six maxima, three of prominence
    # 0.57 = max - min and three of prominence 0.27 (48% of the range). The default threshold
    # (10% of the range) counts all six, a threshold above 48% the three lobes.
    assert count_peaks(res.kappa) == 6
    assert count_peaks(res.kappa, prominence=0.6) == 3
    # The same holds on the other chirality and at another sampling.
    other = analyze(trefoil_points(150, "left"), _frenet_offset(trefoil_points(150, "left"), 0.1))
    assert symmetry_order(other.kappa) == 3 and count_peaks(other.kappa, prominence=0.6) == 3
