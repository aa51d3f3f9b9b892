"""The twisted-knot atlas (issue 9, part B): a sweep of independent studies, serial or on a Dask
cluster with the same numbers (acceptance 4), resumable, its CSV, table and figure; the knot and
curve twist studies of the CLI; relaxing to a minimum, not a saddle."""
import csv
import math
import shutil

import numpy as np
import pytest

import jaxrod as jr
from jaxrod.studies import atlas
from jaxrod.cli import main

# The validation tier (-m validation): sweeps of whole studies, serial and on a Dask cluster.
pytestmark = pytest.mark.validation

PI = math.pi
# Four small studies: the trefoil at D/L = 0.025 and 0.03, N = 40, both sides. Each side ends
# within the span (opening ~ +6.7 pi, tightening ~ -11.5 pi; the paper's rod, D/L = 0.0274:
# +6.46 pi and -11.18 pi at N = 121).
KNOTS, RATIOS, N = ["3_1"], [0.025, 0.03], 40
SETTINGS = atlas.AtlasSettings(span=14.0 * PI, tol=1e-2 * PI)


def comparable(table, *leave_out):
    """Rows with NaN (the snap columns of an end that is not a snap) as None, which compares equal."""
    nan_free = lambda v: None if isinstance(v, float) and math.isnan(v) else v  # noqa: E731
    return [{k: nan_free(v) for k, v in r.items() if k not in leave_out} for r in table]


@pytest.fixture(scope="module")
def serial(tmp_path_factory):
    out = tmp_path_factory.mktemp("atlas_serial")
    seen = []
    rows = atlas.run_atlas(KNOTS, RATIOS, N, settings=SETTINGS, out=str(out), on_row=lambda r, i, n: seen.append((i, n)))
    return out, rows, seen


def test_serial_sweep_finds_every_branch_end(serial):
    out, rows, seen = serial
    assert seen == [(1, 4), (2, 4), (3, 4), (4, 4)]
    assert [(r["D_over_L"], r["side"]) for r in rows] == [(0.025, "plus"), (0.025, "minus"), (0.03, "plus"),
                                                          (0.03, "minus")]
    for r in rows:
        # each end located on its extended system, within the study's bracket
        assert r["kind"] in ("fold", "branch_point") and r["located"] == "yes", r["reason"]
        assert 0 < r["phi_error"] <= SETTINGS.tol and abs(r["phi_star"] - r["phi_study"]) <= r["phi_error"]
        phi = r["phi_star"] / PI
        assert (6.0 < phi < 7.2) if r["side"] == "plus" else (-13.5 < phi < -10.5)  # opening, tightening
    # The tightening side is phi < 0 (jaxrod's right-handed trefoil), told by the contacts gained.
    sides = atlas.tightening_sides(rows)
    assert sides[("3_1", 0.025, N)] == sides[("3_1", 0.03, N)] == "minus"
    assert comparable(atlas.read_atlas(str(out))) == comparable(rows)  # the CSV holds exactly the returned numbers


def test_dask_local_cluster_gives_the_serial_numbers(serial, tmp_path, capsys):
    """Acceptance 4: the CLI, given a local Dask cluster's scheduler address (2 worker processes),
    finishes an interrupted sweep on it: the two cases left (both sides at D/L = 0.03) run one per
    worker, and the rows are identical to the serial ones (every column but the time taken, not merely close)."""
    distributed = pytest.importorskip("distributed")  # a test dependency: installed by '.[test]'
    out, rows, _ = serial
    (tmp_path / "cli").mkdir()
    shutil.copy(out / "atlas.json", tmp_path / "cli" / "atlas.json")
    lines = (out / "atlas.csv").read_text().splitlines()
    # Interrupted with the two cases at D/L = 0.025 done (the header and two rows).
    (tmp_path / "cli" / "atlas.csv").write_text("\n".join(lines[:3]) + "\n")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client, distributed.get_task_stream(client) as tasks:
        status = main(["atlas", "--knots", "3_1", "--ratios", "0.025,0.03", "--N", "40", "--span", "14pi",
                       "--tol", "0.01pi", "--out", str(tmp_path / "cli"), "--scheduler", cluster.scheduler_address,
                       "--quiet", "--no-figures"])
    capsys.readouterr()
    assert status == 0
    got = atlas.read_atlas(str(tmp_path / "cli"))
    assert comparable(got, "seconds") == comparable(rows, "seconds")
    assert len({t["worker"] for t in tasks.data}) == 2, tasks.data  # the two cases ran in parallel


def test_interrupted_sweep_resumes_with_the_missing_cases_only(serial, tmp_path):
    out, rows, _ = serial
    shutil.copy(out / "atlas.json", tmp_path / "atlas.json")
    lines = (out / "atlas.csv").read_text().splitlines()
    # Killed while writing the third case's row: two whole rows and half of the third.
    (tmp_path / "atlas.csv").write_text("\n".join(lines[:3]) + "\n" + lines[3][: len(lines[3]) // 2])
    redone = []
    again = atlas.run_atlas(KNOTS, RATIOS, N, settings=SETTINGS, out=str(tmp_path),
                            on_row=lambda r, i, n: redone.append((r["D_over_L"], r["side"], i)))
    assert redone == [(0.03, "plus", 3), (0.03, "minus", 4)]
    assert [r["phi_star"] for r in again] == [r["phi_star"] for r in rows]
    with open(tmp_path / "atlas.csv", newline="") as f:
        assert len(list(csv.DictReader(f))) == 4
    with pytest.raises(ValueError, match="other settings"):
        atlas.run_atlas(KNOTS, RATIOS, N, settings=atlas.AtlasSettings(span=10 * PI, tol=1e-2 * PI), out=str(tmp_path))


def test_report_and_figure(serial, tmp_path):
    out, rows, _ = serial
    # A second N for one case (as a convergence study adds) and a case without an end.
    extra = [dict(rows[0], N=60, phi_star=rows[0]["phi_star"] - 0.01 * PI,
                  phi_star_over_pi=rows[0]["phi_star_over_pi"] - 0.01),
             dict(rows[1], D_over_L=0.035, phi_star=math.nan, phi_star_over_pi=math.nan, kind="none")]
    atlas.write_rows(str(tmp_path / "atlas.csv"), atlas.FIELDS, rows + extra)
    shutil.copy(out / "atlas.json", tmp_path / "atlas.json")
    text = open(atlas.report(str(tmp_path))).read()
    assert "| 3_1 | 0.025 | 40 | minus |" in text and "| yes |" in text and "none" in text
    assert "## Convergence in N" in text and "N = 40:" in text and "N = 60:" in text and "-0.0100 pi" in text
    import matplotlib.image

    image = matplotlib.image.imread(atlas.figures(str(tmp_path)))
    assert image.ndim == 3 and min(image.shape[:2]) > 300 and image[..., :3].std() > 0.05
    image = matplotlib.image.imread(tmp_path / "atlas_convergence.png")  # the case at N = 40 and 60
    assert image.ndim == 3 and min(image.shape[:2]) > 200 and image[..., :3].std() > 0.05


def test_cli_atlas_writes_csv_table_and_figure(serial, tmp_path, capsys):
    out, rows, _ = serial
    shutil.copytree(out, tmp_path / "a")  # everything done: the CLI resumes, computes nothing, draws
    status = main(["atlas", "--knots", "3_1", "--ratios", "0.025,0.03", "--N", "40", "--span", "14pi",
                   "--tol", "0.01pi", "--out", str(tmp_path / "a"), "--quiet"])
    printed = capsys.readouterr().out
    assert status == 0
    assert "3_1  D/L = 0.025   N = 40   plus  phi* = +" in printed
    for name in ("atlas.csv", "atlas.json", "atlas.md", "atlas.png"):
        assert (tmp_path / "a" / name).stat().st_size > 0


def test_relax_to_minimum_leaves_the_saddle_of_a_symmetric_drawing():
    """The cinquefoil drawn as the symmetric torus knot T(2, 5) relaxes onto a saddle (one
    negative eigenvalue); relax_to_minimum pushes off it to a stable state of lower energy, and
    follow_twist refuses to start from the saddle."""
    scene = jr.knot("5_1", D=8.0, L=292.0, N=61)
    saddle = jr.relax(scene, 0.0, options=jr.RelaxOptions(negative_tol=1e-6))
    assert saddle.stability.n_negative == 1
    minimum = jr.relax_to_minimum(scene, 0.0)
    assert minimum.stability.stable and minimum.energy < saddle.energy
    assert abs(minimum.Lk - saddle.Lk) < 1e-9  # the same knot, the same linking number
    with pytest.raises(ValueError, match="unstable"):
        jr.follow_twist(scene, 0.0, 1.0, start=saddle)


def test_cli_knot_from_a_curve_file_equals_the_named_knot(tmp_path, capsys):
    """Any closed curve from a file: the trefoil's own points, written to CSV, give the study of
    `jaxrod knot 3_1` exactly."""
    points = jr.model.scenes.knot_points("3_1", 400)  # the points jr.knot samples for N <= 100
    np.savetxt(tmp_path / "trefoil.csv", points, delimiter=",", header="x,y,z", comments="")
    common = ["--D", "8", "--L", "300", "--N", "40", "--phi-min", "-0.5pi", "--phi-max", "0.5pi", "--quiet",
              "--no-figures", "--json"]
    assert main(["knot", "3_1", *common, "--out", str(tmp_path / "named")]) == 0
    assert main(["knot", "--curve", str(tmp_path / "trefoil.csv"), *common, "--out", str(tmp_path / "curve")]) == 0
    capsys.readouterr()
    named = (tmp_path / "named" / "branch.csv").read_text()
    assert named == (tmp_path / "curve" / "branch.csv").read_text()
    assert len(named.splitlines()) >= 4


def test_cases_are_checked_before_any_work():
    cases = atlas.atlas_cases(["3_1", "4_1"], [0.03, 0.025], [40, 60], sides="minus")
    assert [(c.knot, c.D_over_L, c.N, c.side) for c in cases][:3] == [("3_1", 0.025, 40, "minus"),
                                                                     ("3_1", 0.025, 60, "minus"),
                                                                     ("3_1", 0.03, 40, "minus")]
    assert len(cases) == 8
    with pytest.raises(ValueError, match="ratios: 5_2 at D/L = 0.05"):  # L/D = 20 < 24.68: no such knot
        atlas.atlas_cases(["5_2"], [0.05], 60)
    with pytest.raises(ValueError, match="^N: 3_1 at D/L = 0.01"):  # edges longer than D
        atlas.atlas_cases(["3_1"], [0.01], 60)
    with pytest.raises(ValueError, match="sides"):
        atlas.atlas_cases(["3_1"], [0.03], 40, sides=("left",))


def test_accuracy_mode_gives_each_row_its_extrapolation_and_error_bar(tmp_path):
    """With ``accuracy`` each case's end is also followed at N, 4N/3, 5N/3 (each level from the
    previous one's state) and extrapolated: the row holds the extrapolated value, its error bar,
    whether the accuracy was reached and every level; the table and the figure show them."""
    from jaxrod.studies.accuracy import richardson

    settings = atlas.AtlasSettings(span=10.0 * PI, tol=1e-2 * PI, accuracy=0.5 * PI)
    (row,) = atlas.run_atlas(["3_1"], [0.03], N, settings=settings, out=str(tmp_path), sides="plus")
    levels = [tuple(map(float, item.split(":"))) for item in row["accuracy_levels"].split(";")]
    assert [int(n) for n, _ in levels] == list(atlas.accuracy_levels(N)) == [40, 53, 67]
    ext = richardson([n for n, _ in levels], [v * PI for _, v in levels])
    assert abs(row["phi_extrapolated"] - ext.value) < 1e-5 * PI  # the levels are stored to 1e-6 pi
    assert 0.0 < row["extrapolation_error"] < math.inf and 6.0 < row["phi_extrapolated"] / PI < 7.5
    assert row["accuracy_reached"] == ("yes" if row["extrapolation_error"] <= settings.accuracy else "no")
    assert "accuracy mode:" in row["reason"]
    assert comparable(atlas.read_atlas(str(tmp_path))) == comparable([row])
    report = open(atlas.report(str(tmp_path))).read()
    assert "## Converged in N (accuracy mode)" in report and f"{row['phi_extrapolated'] / PI:+.4f}" in report
    assert atlas.figures(str(tmp_path)).endswith("atlas.png")
    with pytest.raises(ValueError, match="accuracy"):
        atlas.AtlasSettings(accuracy=0.0)
