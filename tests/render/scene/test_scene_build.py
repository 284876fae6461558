"""The scene stage: media resolved from presets, meshes placed and checked, the camera framing its
objects, the sun from the site's sun path, and the auto time window against analytic arrivals."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from geometry.meshio import write_ply
from pipeline.schema.scene import (
    CameraConfig,
    FilmConfig,
    MediumConfig,
    ObjectConfig,
    SceneConfig,
    SkyConfig,
    SunConfig,
)
from render.scene import optics
from render.scene.build import build_scene, frame_camera, medium_optics, site_sun_direction
from render.scene.model import Scene, project_to_pixel
from render.scene.shapes import box_mesh, frame_mesh
from render.scene.stage import run_scene_stage


def box_scene(**overrides) -> SceneConfig:
    fields = dict(
        media={"snow": MediumConfig(preset="penitente_firn")},
        objects=[ObjectConfig(name="block", shape="box", medium="snow", center=(0, 0, -0.5), size=(2, 2, 1))],
        camera=CameraConfig(
            placement="look_at", origin=(0, 0, 5), target=(0, 0, 0), up=(0, 1, 0), width=32, height=24, fov=40
        ),
        sun=SunConfig(direction=(0, 0, 1), kind="directional"),
        sky=SkyConfig(radiance=0.0),
        film=FilmConfig(mode="transient", temporal_bins=10, window="auto", window_tail_opl=0.0),
    )
    fields.update(overrides)
    return SceneConfig(**fields)


def test_frame_mesh_is_one_watertight_ring_with_the_right_volume():
    import manifold3d

    v, f = frame_mesh((0.0, 0.0), (2.0, 1.0), 0.5, 0.0, 1.0)
    solid = manifold3d.Manifold(manifold3d.Mesh(vert_properties=v, tri_verts=f))
    assert solid.status() == manifold3d.Error.NoError
    assert solid.genus() == 1
    assert solid.volume() == pytest.approx(3.0 * 2.0 - 2.0 * 1.0)


def test_media_take_the_render_form_their_kind_calls_for():
    snow = medium_optics(MediumConfig(preset="penitente_firn"), "snow")
    full = optics.load_preset("penitente_firn")
    # Diffraction removed by default for grains: sigma_s halves, g_G = 2g - 1, sigma_s (1 - g) kept.
    np.testing.assert_allclose(snow.sigma_s, np.asarray(full.sigma_s) / 2)
    np.testing.assert_allclose(
        np.asarray(snow.sigma_s) * (1 - np.asarray(snow.g)), np.asarray(full.sigma_s) * (1 - np.asarray(full.g))
    )
    assert snow.boundary == "null" and snow.region_ior == 1.0
    thesis = medium_optics(MediumConfig(preset="thesis_set_6"), "t")
    assert thesis.sigma_s == (9.0, 5.5, 3.35) and thesis.g == (0.87,) * 3 and thesis.boundary == "dielectric"
    matched = medium_optics(MediumConfig(preset="thesis_set_6", boundary="null", metres_per_unit=0.5), "t")
    assert matched.sigma_s == (18.0, 11.0, 6.7) and matched.region_ior == 1.0
    with pytest.raises(ValueError, match="scene.media.x: metres_per_unit applies to thesis"):
        medium_optics(MediumConfig(preset="penitente_firn", metres_per_unit=2.0), "x")


def test_scene_folder_round_trips_and_holds_watertight_meshes(tmp_path):
    summary = run_scene_stage(box_scene(), tmp_path)
    scene = Scene.load(tmp_path / "scene.json")
    assert [s.name for s in scene.shapes] == ["block"] and scene.shapes[0].kind == "null"
    assert (tmp_path / "meshes" / "block.ply").stat().st_size > 0
    core = json.loads((tmp_path / "ptpb_scene.json").read_text())
    assert core["shapes"][0]["mesh"] == "meshes/block.ply" and core["film"]["frame_mode"] == "bins"
    derived = json.loads((tmp_path / "optics.json").read_text())["snow"]["derived"]
    # penitente snow r_d (render/scene/OPTICS.md §8): 0.903 / 0.956 / 0.969.
    np.testing.assert_allclose(derived["diffuse_albedo"], [0.903, 0.956, 0.969], atol=0.002)
    assert summary["media"]["snow"]["form"] == "diffraction_removed"


def test_auto_window_matches_the_analytic_first_and_last_arrivals(tmp_path):
    # Sun at the zenith, camera 5 m above the top face z = 0 looking down: a surface point x at
    # distance rho from the axis is lit at (P0 - x).s = C_z + R_s and seen after sqrt(25 + rho^2).
    scene, _ = build_scene(box_scene(), tmp_path)
    lo, hi = np.array([-1.0, -1.0, -1.0]), np.array([1.0, 1.0, 0.0])
    centre, radius = 0.5 * (lo + hi), float(np.linalg.norm(hi - 0.5 * (lo + hi)))
    sun_leg = centre[2] + radius
    earliest = sun_leg + 5.0
    # The film's half-diagonal footprint at 5 m, clipped to the 2 m block.
    tx = math.tan(math.radians(20))
    corner = min(1.0, 5 * tx), min(1.0, 5 * tx * 24 / 32)
    latest = sun_leg + math.sqrt(25 + corner[0] ** 2 + corner[1] ** 2)
    film = scene.film
    end = film.start_opl + film.temporal_bins * film.bin_width_opl
    assert film.start_opl <= earliest <= film.start_opl + film.bin_width_opl
    # The window is sampled on the pixel grid: the block's corner may fall up to a pixel (0.11 m) short,
    # which moves its arrival by < 0.05 m of OPL.
    assert latest - 0.05 <= end <= latest + 0.05


def test_framing_camera_keeps_the_bounding_sphere_inside_the_image():
    cfg = CameraConfig(view_azimuth_deg=200, view_elevation_deg=35, fov=40, width=96, height=64)
    centre, radius = np.array([4.0, 4.0, 0.0]), 5.0
    camera = frame_camera(cfg, centre, radius)
    # Points on the sphere's silhouette seen from the camera project inside the film.
    view = centre - np.asarray(camera.origin)
    view /= np.linalg.norm(view)
    ortho = np.cross(view, [0, 0, 1.0])
    ortho /= np.linalg.norm(ortho)
    up = np.cross(ortho, view)
    rim = [centre + radius * (math.cos(a) * ortho + math.sin(a) * up) for a in np.linspace(0, 2 * math.pi, 16)]
    px = project_to_pixel(camera, np.array(rim))
    assert np.all(px[:, 0] > 0) and np.all(px[:, 0] < 96) and np.all(px[:, 1] > 0) and np.all(px[:, 1] < 64)
    assert px[:, 1].min() < 3 or px[:, 1].max() > 61  # and it fits tightly along the narrower axis


def test_site_sun_at_noon_has_the_noon_zenith_angle():
    from geometry import sunpath

    latitude, day = -30.1, 350
    to_sun = site_sun_direction(latitude, day, 12.0)
    zenith = math.degrees(math.acos(to_sun[2]))
    delta = math.degrees(float(sunpath.declination(day)))
    assert zenith == pytest.approx(abs(latitude - delta), abs=1e-6)
    assert to_sun[1] > 0 or abs(latitude - delta) < 1e-9  # the noon sun stands north of a site south of it
    with pytest.raises(ValueError, match="below the horizon"):
        site_sun_direction(latitude, day, 2.0)


def test_a_mesh_that_is_not_watertight_is_refused_with_its_name(tmp_path):
    v, f = box_mesh()
    write_ply(tmp_path / "open.ply", v, f[:-1])  # one triangle missing
    cfg = box_scene(objects=[ObjectConfig(name="broken", shape="ply", path=str(tmp_path / "open.ply"), medium="snow")])
    with pytest.raises(ValueError, match="object 'broken'.*not a closed manifold"):
        build_scene(cfg, tmp_path / "out")
    write_ply(tmp_path / "inside_out.ply", v, f[:, ::-1])
    cfg = box_scene(
        objects=[ObjectConfig(name="flipped", shape="ply", path=str(tmp_path / "inside_out.ply"), medium="snow")]
    )
    with pytest.raises(ValueError, match="object 'flipped'.*flip its faces"):
        build_scene(cfg, tmp_path / "out")


def test_penitentes_without_a_geometry_mesh_is_a_clear_error(tmp_path):
    cfg = SceneConfig()
    with pytest.raises(FileNotFoundError, match="run the geometry stage first"):
        build_scene(cfg, tmp_path)


def test_a_depth_cap_that_truncates_dense_snow_is_named_but_the_demo_is_not():
    from pipeline.config import load_config
    from render.scene.stage import depth_cap_problems

    demo = load_config("configs/demo.yaml").scene  # albedo 0.946 at most: 3 % left after 63 scatterings
    assert depth_cap_problems(demo.max_depth, {"snow": medium_optics(demo.media["snow"], "snow")}) == []
    dense = medium_optics(MediumConfig(preset="penitente_firn"), "snow")  # albedo 0.9999x
    (problem,) = depth_cap_problems(64, {"snow": dense})
    assert problem.startswith("scene.max_depth=64 truncates light in medium 'snow'") and "max_depth: -1" in problem
    assert depth_cap_problems(-1, {"snow": dense}) == []
