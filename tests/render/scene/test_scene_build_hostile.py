"""Hostile meshes through the scene stage: each is refused with a reason that names its object, or
builds a scene that renders with finite values."""

from __future__ import annotations

import numpy as np
import pytest

from geometry.meshio import write_ply
from pipeline.schema.scene import (
    CameraConfig,
    CoefficientsConfig,
    FilmConfig,
    MediumConfig,
    ObjectConfig,
    SceneConfig,
    SkyConfig,
    SunConfig,
)
from render.engine import load_core_scene
from render.ptpb.api import render
from render.scene.build import build_scene
from render.scene.shapes import box_mesh
from render.scene.stage import run_scene_stage


def ply_scene(path) -> SceneConfig:
    return SceneConfig(
        media={
            "snow": MediumConfig(coefficients=CoefficientsConfig(sigma_s=(3.0, 2.5, 2.0), sigma_a=(0.3, 0.1, 0.05)))
        },
        objects=[ObjectConfig(name="hostile", shape="ply", path=str(path), medium="snow")],
        camera=CameraConfig(
            placement="look_at", origin=(0, -3, 2), target=(0, 0, 0), up=(0, 0, 1), width=12, height=8, fov=45
        ),
        sun=SunConfig(direction=(0.3, -0.2, 1.0), kind="directional", irradiance=100.0),
        sky=SkyConfig(radiance=0.0),
        film=FilmConfig(mode="transient", temporal_bins=6, window="auto", window_tail_opl=0.5),
    )


def box_with(extra_vertices=(), extra_faces=()):
    v, f = box_mesh()
    v = np.vstack([v, np.asarray(extra_vertices, np.float32).reshape(-1, 3)])
    f = np.vstack([f, np.asarray(extra_faces, np.uint32).reshape(-1, 3)])
    return v, f


def nan_box():
    v, f = box_mesh()
    v[3, 1] = np.nan
    return v, f


def inf_box():
    v, f = box_mesh()
    v[5, 2] = np.inf
    return v, f


REFUSED = {
    "empty": ((np.zeros((0, 3), np.float32), np.zeros((0, 3), np.uint32)), "the mesh is empty"),
    "fin": (
        box_with([[2, 2, 2]], [[0, 1, 8]]),
        r"not a closed manifold \(NotManifold\)",
    ),  # an extra triangle on an edge
    "nan": (nan_box(), "NaN or infinite vertices"),
    "inf": (inf_box(), "NaN or infinite vertices"),
    # A zero-area triangle with three distinct vertices (one on the edge 0-1) makes that edge non-manifold.
    "sliver": (box_with([[0.0, -0.5, -0.5]], [[0, 8, 1]]), r"not a closed manifold \(NotManifold\)"),
    "inverted": ((box_mesh()[0], box_mesh()[1][:, ::-1].copy()), "encloses no volume .*flip its faces"),
    "out_of_range": (box_with([], [[0, 1, 2]]), "face 12 refers to vertex 99, but the mesh has 8 vertices"),
}


@pytest.mark.parametrize("case", sorted(REFUSED))
def test_a_hostile_mesh_is_refused_with_the_object_name_and_reason(tmp_path, case):
    (v, f), reason = REFUSED[case]
    write_ply(tmp_path / "mesh.ply", v, f)
    if case == "out_of_range":  # write_ply refuses such faces: patch the last index of the file (int32)
        data = bytearray((tmp_path / "mesh.ply").read_bytes())
        data[-4:] = np.int32(99).tobytes()
        (tmp_path / "mesh.ply").write_bytes(bytes(data))
    with pytest.raises(ValueError, match=f"objects? 'hostile'.*{reason}"):
        build_scene(ply_scene(tmp_path / "mesh.ply"), tmp_path / "out")


def test_a_truncated_ply_is_refused_with_the_object_name(tmp_path):
    write_ply(tmp_path / "mesh.ply", *box_mesh())
    data = (tmp_path / "mesh.ply").read_bytes()
    (tmp_path / "mesh.ply").write_bytes(data[: len(data) - 20])
    with pytest.raises(ValueError, match="scene.objects 'hostile': cannot read mesh file"):
        build_scene(ply_scene(tmp_path / "mesh.ply"), tmp_path / "out")


def test_degenerate_triangles_that_keep_the_mesh_closed_build_and_render_finite(tmp_path):
    # Zero-area triangles that repeat a vertex: manifold3d keeps the box closed, Embree never hits them.
    v, f = box_with([], [[0, 0, 1], [5, 7, 7]])
    write_ply(tmp_path / "mesh.ply", v, f)
    run_scene_stage(ply_scene(tmp_path / "mesh.ply"), tmp_path / "scene")
    scene = load_core_scene(tmp_path / "scene")
    result = render(
        scene,
        {
            "iterations": 2,
            "light_paths_per_iteration": 2000,
            "initial_beam_radius": 0.05,
            "max_depth": 16,
            "seed": 1,
            "threads": 2,
        },
    )
    assert np.isfinite(result.steady).all() and np.isfinite(result.frames).all()
    assert result.steady.sum() > 0
