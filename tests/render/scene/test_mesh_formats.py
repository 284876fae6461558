"""A scene object given as an ASCII PLY, an OBJ or an STL file builds and renders like the same mesh
in our binary PLY, and a file that is not a mesh is refused with its name."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from geometry.meshio import read_mesh, write_ply
from render.engine import load_core_scene
from render.ptpb.api import render
from render.scene.shapes import box_mesh
from render.scene.stage import run_scene_stage
from tests.render.scene.test_scene_build_hostile import ply_scene

SETTINGS = {
    "iterations": 2,
    "light_paths_per_iteration": 4000,
    "initial_beam_radius": 0.05,
    "max_depth": 16,
    "seed": 3,
    "threads": 2,
}


def write_in_format(path, vertices, faces):
    if path.suffix == ".ply" and path.stem.endswith("binary"):
        write_ply(path, vertices, faces)
    else:
        mesh = trimesh.Trimesh(vertices=vertices.astype(np.float64), faces=faces, process=False)
        mesh.export(path, encoding="ascii") if path.suffix == ".ply" else mesh.export(path)
    return path


def render_mesh_file(path, tmp_path):
    run_scene_stage(ply_scene(path), tmp_path / f"scene-{path.name}")
    return render(load_core_scene(tmp_path / f"scene-{path.name}"), SETTINGS)


@pytest.fixture(scope="module")
def box():
    v, f = box_mesh((-0.5, -0.5, -0.5), (0.5, 0.5, 0.5))
    return np.asarray(v, np.float32), np.asarray(f, np.uint32)


@pytest.mark.parametrize("name", ["box_ascii.ply", "box.obj", "box.stl"])
def test_other_formats_read_back_the_same_surface(tmp_path, box, name):
    v, f = box
    back_v, back_f = read_mesh(write_in_format(tmp_path / name, v, f))
    assert back_f.shape == f.shape and back_v.shape == v.shape  # STL's corners are merged back to 8 vertices
    # The same triangles, whatever the vertex numbering: compare each face's corner positions.
    original = np.sort(v[f.astype(np.int64)].reshape(len(f), -1), axis=0)
    read = np.sort(back_v[back_f.astype(np.int64)].reshape(len(back_f), -1), axis=0)
    np.testing.assert_allclose(read, original, atol=1e-6)


def test_ascii_ply_obj_and_stl_objects_render_like_binary_ply(tmp_path, box):
    v, f = box
    reference = render_mesh_file(write_in_format(tmp_path / "box_binary.ply", v, f), tmp_path)
    assert reference.steady.mean() > 0
    for name in ("box_ascii.ply", "box.obj", "box.stl"):
        result = render_mesh_file(write_in_format(tmp_path / name, v, f), tmp_path)
        assert np.isfinite(result.steady).all()
        # Same geometry, same keyed random streams: the images agree to float rounding of the vertices.
        np.testing.assert_allclose(result.steady, reference.steady, rtol=1e-4, atol=1e-6 * reference.steady.max())
        np.testing.assert_allclose(result.frames, reference.frames, rtol=1e-4, atol=1e-6 * reference.frames.max())


@pytest.mark.parametrize(("name", "content"), [("junk.obj", "this is not a mesh\n"), ("junk.stl", "solid x\n")])
def test_a_file_that_is_not_a_mesh_is_refused_with_its_name(tmp_path, name, content):
    (tmp_path / name).write_text(content)
    with pytest.raises(ValueError, match=f"scene.objects 'hostile'.*{name}"):
        run_scene_stage(ply_scene(tmp_path / name), tmp_path / "scene")


def test_an_unknown_mesh_format_is_refused(tmp_path):
    (tmp_path / "box.fbx").write_bytes(b"\0" * 16)
    with pytest.raises(ValueError, match=r"unsupported mesh format '\.fbx'; use one of \.ply, \.obj, \.stl"):
        read_mesh(tmp_path / "box.fbx")
