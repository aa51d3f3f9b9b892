"""VTK export of rod states (for ParaView): the file is read back and checked field by field."""
import numpy as np
import pytest

from jaxrod.io.export import write_vtk
from jaxrod.model.scenes import trefoil_points


def _read_legacy_vtk(path):
    """A minimal reader of what write_vtk writes: points, polylines, point scalars."""
    lines = open(path).read().split("\n")
    assert lines[0] == "# vtk DataFile Version 3.0" and lines[2] == "ASCII" and lines[3] == "DATASET POLYDATA"
    i = 4
    head = lines[i].split()
    n = int(head[1])
    points = np.array([[float(v) for v in lines[i + 1 + k].split()] for k in range(n)])
    i += 1 + n
    head = lines[i].split()
    n_lines, size = int(head[1]), int(head[2])
    cells = [[int(v) for v in lines[i + 1 + k].split()] for k in range(n_lines)]
    assert sum(len(c) for c in cells) == size and all(c[0] == len(c) - 1 for c in cells)
    i += 1 + n_lines
    assert lines[i] == f"POINT_DATA {n}"
    i += 1
    scalars = {}
    while i < len(lines) and lines[i]:
        name = lines[i].split()[1]
        assert lines[i + 1] == "LOOKUP_TABLE default"
        scalars[name] = np.array([float(v) for v in lines[i + 2: i + 2 + n]])
        i += 2 + n
    return points, [c[1:] for c in cells], scalars


def test_write_vtk_round_trip(tmp_path):
    x = trefoil_points(50)
    stripe = x + 0.1 * np.array([0.0, 0.0, 1.0])
    kappa = np.linspace(0.0, 1.0, 50)
    path = write_vtk(tmp_path / "state.vtk", x, stripe, point_data={"kappa_L": kappa})
    points, cells, scalars = _read_legacy_vtk(path)
    assert np.array_equal(points, np.vstack([x, stripe]))  # repr: exact round trip
    assert cells[0] == list(range(50)) + [0] and cells[1] == list(range(50, 100)) + [50]  # closed loops
    assert np.array_equal(scalars["line"], np.repeat([0.0, 1.0], 50))
    assert np.array_equal(scalars["kappa_L"][:50], kappa) and np.all(np.isnan(scalars["kappa_L"][50:]))
    # Open, centreline only.
    points, cells, _ = _read_legacy_vtk(write_vtk(tmp_path / "open.vtk", x, closed=False))
    assert len(points) == 50 and cells == [list(range(50))]
    with pytest.raises(ValueError, match="point_data"):
        write_vtk(tmp_path / "bad.vtk", x, point_data={"k": kappa[:10]})
    with pytest.raises(ValueError, match="x must be finite"):
        write_vtk(tmp_path / "bad.vtk", np.full((5, 3), np.nan))


def test_every_branch_column_has_a_unit():
    from jaxrod.io.records import ROW_KEYS, ROW_UNITS

    assert set(ROW_KEYS) <= set(ROW_UNITS) and "lambda_j" in ROW_UNITS and "direction" in ROW_UNITS
