"""Output formats of the result store: meshes from the organised grid, STL, OBJ and E57, each read
back by an independent library (trimesh, pye57) and compared with the result's own points."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from cli_steps import assert_one_line, run

from processing.geometry.mesh import grid_triangles
from rig import api
from rig.store import results

trimesh = pytest.importorskip("trimesh")


def _plane(rows: int, cols: int) -> np.ndarray:
    yy, xx = np.mgrid[0:rows, 0:cols].astype(np.float64)
    return np.dstack([0.5 * xx, 0.5 * yy, 0.1 * xx])  # a gently tilted plane, 0.5 mm pixels


def test_a_whole_grid_gives_two_triangles_per_cell_of_consistent_winding() -> None:
    grid = _plane(7, 9)
    faces = grid_triangles(grid, np.ones((7, 9), bool))
    assert faces.shape == (2 * 6 * 8, 3)
    corners = grid.reshape(-1, 3)[faces]
    normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    assert np.all(normals[:, 2] < 0) or np.all(normals[:, 2] > 0)  # one side of the surface faces the camera
    mesh = trimesh.Trimesh(grid.reshape(-1, 3), faces, process=False)
    assert mesh.is_winding_consistent and mesh.area == pytest.approx(0.5 * 6 * 0.5 * 8 * np.sqrt(1 + 0.2**2))


def test_triangles_only_between_valid_neighbours() -> None:
    mask = np.ones((7, 9), bool)
    mask[3, 4] = False  # an interior pixel: the six triangles around it go
    faces = grid_triangles(_plane(7, 9), mask)
    assert len(faces) == 2 * 6 * 8 - 6
    assert faces.max() == mask.sum() - 1  # vertices are the valid pixels in C order


def test_the_mesh_is_cut_where_depth_jumps() -> None:
    grid = _plane(7, 9)
    grid[:, 5:, 2] += 40.0  # a 40 mm step between columns 4 and 5 (pixels are 0.5 mm apart)
    faces = grid_triangles(grid, np.ones((7, 9), bool))
    assert len(faces) == 2 * 6 * 8 - 2 * 6  # the column of cells across the step
    left = faces.reshape(-1) % 9
    assert not np.any((left.reshape(-1, 3) == 4).any(axis=1) & (left.reshape(-1, 3) == 5).any(axis=1))


@pytest.fixture
def all_formats(small_capture, tmp_path: Path) -> tuple[Any, Path]:
    result = api.process(small_capture.capture, small_capture.calibration, api.ProcessOptions(correction="none"))
    names = [n for n in results.FORMATS if results.FORMATS[n].missing_library() is None]
    api.write_outputs(result, tmp_path / "out", formats=names)
    return result, tmp_path / "out"


def test_mesh_files_read_back_with_trimesh(all_formats) -> None:
    result, out = all_formats
    points = result.valid_points().astype(np.float32)
    faces = grid_triangles(result.points, result.mask)
    assert len(faces) > 1.5 * len(points)  # a closed-ish surface: about two triangles per valid pixel
    ply = trimesh.load(out / results.MESH_PLY, process=False)
    assert len(ply.vertices) == len(points) and np.array_equal(ply.faces, faces)
    np.testing.assert_array_equal(ply.vertices.astype(np.float32), points)
    obj = trimesh.load(out / results.MESH_OBJ, process=False)
    assert np.array_equal(obj.faces, faces)
    np.testing.assert_allclose(obj.vertices, points, rtol=1e-6, atol=1e-5)
    stl = trimesh.load(out / results.MESH_STL, process=False)
    assert len(stl.faces) == len(faces)
    np.testing.assert_allclose(stl.triangles, points[faces], rtol=1e-6, atol=1e-5)
    np.testing.assert_allclose(stl.face_normals, trimesh.Trimesh(points, faces, process=False).face_normals, atol=1e-4)
    listed = results.read_report(out)["files"]  # the report names every file it holds
    assert {listed[k] for k in ("points", "mesh_ply", "mesh_stl", "mesh_obj")} == {
        results.POINTS,
        results.MESH_PLY,
        results.MESH_STL,
        results.MESH_OBJ,
    }


def test_points_e57_reads_back_with_pye57(all_formats) -> None:
    pye57 = pytest.importorskip("pye57")
    result, out = all_formats
    scan = pye57.E57(str(out / results.POINTS_E57)).read_scan_raw(0)
    read = np.column_stack([scan["cartesianX"], scan["cartesianY"], scan["cartesianZ"]])
    np.testing.assert_allclose(read, result.valid_points(), rtol=0, atol=1e-9)


def test_formats_are_checked_before_any_work(capsys, small_capture, tmp_path, monkeypatch) -> None:
    capture, calibration = small_capture.capture, small_capture.calibration
    code, err = run(
        capsys, "process", capture, "--calibration", calibration, "--format", "ply,vrml", "-o", tmp_path / "a"
    )
    assert_one_line(code, err, "--format", "expected names from ply, mesh-ply, stl, obj, e57", "found vrml")
    monkeypatch.setitem(sys.modules, "pye57", None)  # as if the e57 extra were not installed
    code, err = run(capsys, "process", capture, "--calibration", calibration, "--format", "e57", "-o", tmp_path / "b")
    assert_one_line(code, err, "--format e57", "pip install 'fpp-rig[e57]'")
    code, err = run(capsys, "process", capture, "--format", "stl", "-o", tmp_path / "c")
    assert_one_line(code, err, "--format stl", "--calibration")
    assert not any((tmp_path / n).exists() for n in "abc")


def test_default_formats_write_what_rig_process_always_wrote(capsys, small_capture, tmp_path) -> None:
    out = tmp_path / "out"
    assert (
        run(capsys, "process", small_capture.capture, "--calibration", small_capture.calibration, "-o", out, "-q")[0]
        == 0
    )
    assert sorted(p.name for p in out.iterdir()) == sorted(
        [
            results.REPORT,
            results.PHASE,
            results.MASK,
            results.PREVIEW,
            results.HEIGHT,
            results.UNCERTAINTY,
            results.POINTS,
        ]
    )
