"""The tiled landscape (render/core/DESIGN.md §13): the grown tile's periodic surface placed tiles x tiles
times as Embree instances of one mesh and closed by walls around the outside. Where the camera sees only the
grown tile's middle, the tiled render equals the untiled one (the geometry stage's closed box) within noise;
anywhere it equals the same field placed by hand as one big mesh; and the scene holds one tile's triangles."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from geometry import mesh
from geometry.meshio import read_mesh
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
from render.engine import RayEngine
from render.ptpb import load_scene, render
from render.scene.model import Scene
from render.scene.stage import run_scene_stage

N, SPACING = 32, 0.0625  # a 2 m tile
TILE = N * SPACING
BASE = 0.5


def _field(scale: float = 1.0) -> np.ndarray:
    """Periodic E-W rows 1 m apart with bumps along them, 0.6 m crest to trough at scale 1."""
    x = (np.arange(N) + 0.5) * SPACING
    xx, yy = np.meshgrid(x, x)  # h[row = y, col = x], as the geometry stage stores it
    rows = 0.25 * np.cos(4 * np.pi * yy / TILE)
    return scale * (rows + 0.08 * np.sin(2 * np.pi * xx / TILE) * np.cos(2 * np.pi * yy / TILE))


def _geometry(folder, scale: float = 1.0):
    """What the geometry stage leaves for the scene stage: the height field and its closed mesh."""
    h = _field(scale)
    np.savez(folder / "heightfield.npz", height=h, spacing=SPACING)
    mesh.write_ply(folder / "penitentes.ply", mesh.heightfield_solid(h, SPACING, BASE))
    return folder


@pytest.fixture(scope="module")
def geometry_dir(tmp_path_factory):
    folder = _geometry(tmp_path_factory.mktemp("geometry"))
    h = _field()
    mesh.write_ply(folder / "penitentes.ply", mesh.heightfield_solid(h, SPACING, BASE))
    # The same field 3 x 3 times as one closed mesh, centred on the grown tile: copies placed by hand.
    solid = mesh.heightfield_solid(h, SPACING, BASE, tiles=3)
    moved = mesh.TriangleMesh(solid.vertices - np.array([TILE, TILE, 0.0]), solid.faces)
    mesh.write_ply(folder / "by_hand.ply", moved)
    return folder


def _scene(folder, out, objects, *, fov: float = 19.0, width: int = 40, height: int = 30):
    cfg = SceneConfig(
        media={"snow": MediumConfig(coefficients=CoefficientsConfig(sigma_s=200.0, sigma_a=0.5, g=0.0))},
        objects=objects,
        camera=CameraConfig(
            placement="look_at",
            origin=(TILE / 2, TILE / 2 - 0.4, 3.0),
            target=(TILE / 2, TILE / 2, 0.0),
            up=(0, 1, 0),
            width=width,
            height=height,
            fov=fov,
        ),
        sun=SunConfig(kind="directional", elevation_deg=65.0, azimuth_deg=20.0, reference_point=(1.0, 1.0, 0.0)),
        sky=SkyConfig(radiance=0.0),
        film=FilmConfig(mode="transient", temporal_bins=8, window="auto", window_tail_opl=0.3),
        max_depth=-1,
    )
    run_scene_stage(cfg, out, geometry_dir=folder)
    return load_scene(out)


def _render(core, seed: int):
    result = render(core, {"iterations": 24, "frame_mode": "bins", "seed": seed, "threads": 2})
    return result.steady, result.frames


def test_the_copies_and_walls_close_one_solid_and_hold_one_tile(geometry_dir, tmp_path):
    core = _scene(geometry_dir, tmp_path, [ObjectConfig(name="field", shape="penitentes", medium="snow", tiles=7)])
    scene = Scene.load(tmp_path / "scene.json")
    assert [s.name for s in scene.shapes] == ["field", "field_walls"]
    assert len(scene.shapes[0].offsets) == 49 and scene.shapes[1].offsets is None
    sheet = read_mesh(tmp_path / "meshes" / "field.ply")
    assert len(sheet[1]) == 2 * N * N  # one tile at full resolution
    engine = RayEngine()
    for i, shape in enumerate(core["shapes"]):
        engine.add_mesh(shape["vertices"], shape["faces"], i, shape.get("offsets"))
    engine.commit()
    walls = len(read_mesh(tmp_path / "meshes" / "field_walls.ply")[1])
    assert engine.triangle_count == 2 * N * N + walls
    assert engine.placed_triangle_count == 49 * 2 * N * N + walls
    lower, upper = engine.bounds
    np.testing.assert_allclose(lower[:2], [-3 * TILE, -3 * TILE], atol=1e-5)
    np.testing.assert_allclose(upper[:2], [4 * TILE, 4 * TILE], atol=1e-5)
    # A vertical ray anywhere meets the surface at the height the grown tile has at the same place in it.
    one = RayEngine()
    one.add_mesh(*sheet, 0)
    one.commit()
    rng = np.random.default_rng(3)
    xy = rng.uniform(-3 * TILE, 4 * TILE, (500, 2))
    down = np.tile([0.0, 0.0, -1.0], (500, 1))
    hits = engine.intersect(np.column_stack((xy, np.full(500, 2.0))), down)
    home = one.intersect(np.column_stack((np.mod(xy, TILE), np.full(500, 2.0))), down)
    assert hits.hit.all() and home.hit.all() and np.all(hits.mesh_id == 0)
    np.testing.assert_allclose(hits.t, home.t, atol=1e-5)
    assert np.ptp(hits.t) > 0.4  # the rays met crests and troughs


def test_a_tiled_render_equals_the_untiled_one_where_both_see_the_grown_tile(tmp_path):
    """The middle metre of a 2 m tile of shallow rows (0.18 m crest to trough). Deeper forms pass light between
    tiles by inter-reflection, which an untiled box lacks: with 0.6 m rows the same view is 3.1 % brighter
    tiled, and the tiled render is then the right one (render/core/DESIGN.md §13)."""
    geometry_dir = _geometry(tmp_path, scale=0.3)
    untiled = _scene(geometry_dir, tmp_path / "one", [ObjectConfig(name="field", shape="penitentes", medium="snow")])
    tiled = _scene(
        geometry_dir, tmp_path / "tiled", [ObjectConfig(name="field", shape="penitentes", medium="snow", tiles=5)]
    )
    assert untiled["film"] == tiled["film"]  # the pinned sun keeps the time axis
    a, a_frames = _render(untiled, seed=1)
    b, _ = _render(untiled, seed=2)
    t, t_frames = _render(tiled, seed=1)
    # Same seed: the random streams are keyed by pixel and iteration, so the two renders follow the same paths
    # until one of them leaves the grown tile; they differ by those paths alone, far below the noise between
    # two seeds of one render.
    noise = np.mean((a - b) ** 2)
    assert a.mean() > 0.1 * a.max() and noise > 0
    assert np.mean((t - a) ** 2) < 0.05 * noise
    assert t.mean() / a.mean() == pytest.approx(1.0, abs=0.005)
    sums, reference = t_frames.sum(axis=(1, 2, 3)), a_frames.sum(axis=(1, 2, 3))
    lit = reference > 0.01 * reference.sum()
    assert lit.sum() >= 4
    np.testing.assert_allclose(sums[lit], reference[lit], rtol=0.01)


def test_instances_render_like_the_same_copies_placed_by_hand(geometry_dir, tmp_path):
    """A wide view over the middle 3 x 3 tiles: the instanced field against one 3 x 3 mesh."""
    wide = {"fov": 70.0, "width": 32, "height": 24}
    tiled = _scene(
        geometry_dir,
        tmp_path / "tiled",
        [ObjectConfig(name="field", shape="penitentes", medium="snow", tiles=3)],
        **wide,
    )
    by_hand = _scene(
        geometry_dir,
        tmp_path / "hand",
        [ObjectConfig(name="field", shape="ply", medium="snow", path=str(geometry_dir / "by_hand.ply"))],
        **wide,
    )
    t, t_frames = _render(tiled, seed=4)
    a, a_frames = _render(by_hand, seed=4)
    b, _ = _render(by_hand, seed=5)
    # The same seed follows the same paths through the same surfaces: equal up to float rounding in the
    # instances' frames, far inside the noise between two seeds.
    noise = np.mean((a - b) ** 2)
    assert np.mean((t - a) ** 2) < 1e-3 * noise
    assert t.mean() / a.mean() == pytest.approx(1.0, abs=1e-4)
    np.testing.assert_allclose(t_frames.sum(axis=(1, 2, 3)), a_frames.sum(axis=(1, 2, 3)), rtol=1e-4)


@pytest.mark.mitsuba
def test_mitsuba_instances_render_like_the_copies_placed_by_hand(geometry_dir, tmp_path):
    """The references place the tile with Mitsuba shape instances (a shapegroup with the snow inside), in the
    film tiles that move and scale the scene too; they must render as the same copies in one mesh."""
    pytest.importorskip("mitsuba")
    from render.mitsuba.passes import render_steady

    wide = {"fov": 70.0, "width": 32, "height": 24}
    images = {}
    for name, obj in (
        ("tiled", ObjectConfig(name="field", shape="penitentes", medium="snow", tiles=3)),
        ("hand", ObjectConfig(name="field", shape="ply", medium="snow", path=str(geometry_dir / "by_hand.ply"))),
    ):
        _scene(geometry_dir, tmp_path / name, [obj], **wide)
        # The references' roulette depth, which the reference stage sets from reference.rr_depth.
        scene = dataclasses.replace(Scene.load(tmp_path / name / "scene.json"), rr_depth=20)
        images[name] = [
            render_steady(scene, tmp_path / name, spp=64, spp_per_pass=64, seed=seed, quiet=True, tiles=2)[0]
            for seed in (1, 2)
        ]
    (t1, t2), (h1, h2) = images["tiled"], images["hand"]
    noise = 0.5 * (np.mean((t1 - t2) ** 2) + np.mean((h1 - h2) ** 2))  # twice one render's variance
    assert h1.mean() > 0 and noise > 0
    assert np.mean((t1 - h1) ** 2) < 1.3 * noise
    ratio = (t1.mean() + t2.mean()) / (h1.mean() + h2.mean())
    assert ratio == pytest.approx(1.0, abs=0.02)


def test_tiling_settings_that_cannot_work_are_refused_with_the_fix():
    import pydantic

    with pytest.raises(pydantic.ValidationError, match="tiles must be odd"):
        ObjectConfig(name="field", shape="penitentes", medium="snow", tiles=4)
    with pytest.raises(pydantic.ValidationError, match="tiles applies to shape penitentes only"):
        ObjectConfig(name="block", shape="box", medium="snow", tiles=3)
    media = {"snow": MediumConfig(preset="penitente_firn")}
    with pytest.raises(pydantic.ValidationError, match="drop the snowpack object or set tiles: 1"):
        SceneConfig(
            media=media,
            objects=[
                ObjectConfig(name="field", shape="penitentes", medium="snow", tiles=3),
                ObjectConfig(name="ring", shape="snowpack", medium="snow"),
            ],
        )


def test_a_tiled_field_without_the_geometry_height_field_names_the_missing_file(tmp_path):
    mesh.write_ply(tmp_path / "penitentes.ply", mesh.heightfield_solid(_field(), SPACING, BASE))
    with pytest.raises(FileNotFoundError, match="heightfield.npz.*run the geometry stage first"):
        _scene(tmp_path, tmp_path / "scene", [ObjectConfig(name="field", shape="penitentes", medium="snow", tiles=3)])
