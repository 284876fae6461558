"""Mesh (watertight, volume = height integral, PLY round trip), config errors, site presets, and
the stage's outputs. The stage test uses the demo grid (GeometryConfig defaults) for 4 days so the
mesh checked is the demo's size and kind; the full 40-day demo runs in the slow test."""

from pathlib import Path

import av
import numpy as np
import pydantic
import pytest

from geometry import mesh
from geometry.stage import run_geometry_stage
from pipeline.config import load_raw
from pipeline.schema.geometry import GeometryConfig

SITES = Path(__file__).resolve().parents[2] / "configs" / "presets" / "sites"


def test_solid_is_watertight_and_volume_matches_height_integral():
    rng = np.random.default_rng(3)
    h = 0.2 * rng.standard_normal((48, 48))
    for tiles in (1, 2):
        solid = mesh.heightfield_solid(h, 0.05, 1.5, tiles)
        volume = mesh.manifold_volume(solid)
        assert volume == pytest.approx(mesh.height_integral_volume(h, 0.05, 1.5, tiles), rel=2e-3)


def test_decimated_mesh_stays_manifold_and_ply_round_trips(tmp_path):
    y, x = np.meshgrid(np.arange(64) * 0.05, np.arange(64) * 0.05, indexing="ij")
    h = 0.5 * np.abs(np.sin(np.pi * y / 0.8))  # sharp-crested rows
    solid = mesh.heightfield_solid(h, 0.05, 1.0)
    small = mesh.decimate(solid, 2000)
    assert len(small.faces) <= 2000
    assert mesh.manifold_volume(small) == pytest.approx(mesh.manifold_volume(solid), rel=0.01)
    path = mesh.write_ply(tmp_path / "m.ply", small)
    back = mesh.read_ply(path)
    np.testing.assert_array_equal(back.faces, small.faces)
    np.testing.assert_allclose(back.vertices, small.vertices, atol=1e-5)
    assert mesh.manifold_volume(back) > 0


def test_open_mesh_is_rejected():
    solid = mesh.heightfield_solid(np.zeros((8, 8)), 0.1, 1.0)
    with pytest.raises(ValueError, match="not watertight"):
        mesh.manifold_volume(mesh.TriangleMesh(solid.vertices, solid.faces[:-3]))


@pytest.mark.parametrize("field,value", [("albedo", 1.5), ("grid_cells", 4), ("density", -1.0), ("colour", 1)])
def test_bad_config_values_name_the_field(field, value):
    with pytest.raises(pydantic.ValidationError, match=field):
        GeometryConfig(**{field: value})


def test_initial_wavelength_must_be_resolved():
    with pytest.raises(pydantic.ValidationError, match="geometry.initial_wavelength"):
        GeometryConfig(grid_cells=32, domain_size=8.0, initial_wavelength=0.5)


@pytest.mark.parametrize("preset", sorted(p.name for p in SITES.glob("*.yaml")))
def test_site_presets_validate(preset):
    text = (SITES / preset).read_text()
    assert text.startswith("# ")
    GeometryConfig(**load_raw(SITES / preset)["geometry"])


def test_stage_writes_every_output(tmp_path):
    cfg = GeometryConfig(days=10, snapshots=4)
    summary = run_geometry_stage(cfg, tmp_path, seed=5, quiet=True)
    for name in (
        "heightfield.npz",
        "penitentes.ply",
        "metrics.json",
        "metrics.png",
        "preview.png",
        "hillshade.png",
        "timelapse.mp4",
    ):
        assert (tmp_path / name).stat().st_size > 1000, name
    solid = mesh.read_ply(tmp_path / "penitentes.ply")
    data = np.load(tmp_path / "heightfield.npz")
    expected = mesh.height_integral_volume(data["height"], float(data["spacing"]), cfg.base_thickness)
    assert mesh.manifold_volume(solid) == pytest.approx(expected, rel=0.01)
    assert solid.vertices[:, 0].max() == pytest.approx(cfg.domain_size, rel=1e-6)  # x east, metres
    with av.open(str(tmp_path / "timelapse.mp4")) as video:
        stream = video.streams.video[0]
        assert stream.codec_context.name == "h264"
        frames = [frame.to_ndarray(format="rgb24") for frame in video.decode(stream)]
    assert len(frames) >= 4
    assert np.abs(frames[0].astype(int) - frames[-1]).mean() > 1.0  # the field grows; frames are not one image
    assert summary["triangles"] == len(solid.faces)
    # V4: any relief darkens the field against flat snow of the same local albedo.
    import json

    written = json.loads((tmp_path / "metrics.json").read_text())
    m = written["metrics"]
    assert m["field_albedo"] < m["flat_albedo"]
    assert m["albedo_difference"] == pytest.approx(m["field_albedo"] - cfg.albedo)
    # Issue 18: the spacing is never the domain; the season's history and the aspects are written.
    assert m["dominant_wavelength_m"] <= cfg.domain_size / 2 + 1e-9
    history = written["season_history"]
    assert history["day"] == data["snapshot_days"].tolist()
    for key in ("crest_spacing_m", "crest_to_trough_m", "crest_density_per_m2"):
        assert len(history[key]) == len(history["day"])
    assert sum(written["aspect_histogram"]["fraction"]) == pytest.approx(1.0)


def test_stage_is_deterministic(tmp_path):
    cfg = GeometryConfig(grid_cells=32, domain_size=2.0, days=2, snapshots=2, preview_size=200)
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir(), b.mkdir()
    run_geometry_stage(cfg, a, seed=9, quiet=True)
    run_geometry_stage(cfg, b, seed=9, quiet=True)
    np.testing.assert_array_equal(np.load(a / "heightfield.npz")["height"], np.load(b / "heightfield.npz")["height"])


@pytest.mark.slow
def test_demo_geometry_mesh_is_watertight(tmp_path):
    cfg = GeometryConfig()
    run_geometry_stage(cfg, tmp_path, seed=1, quiet=True)
    assert mesh.manifold_volume(mesh.read_ply(tmp_path / "penitentes.ply")) > 0


@pytest.mark.parametrize("tiles", [1, 3, 5])
def test_tiled_copies_and_walls_close_the_same_solid_as_the_tiled_mesh(tiles):
    """The landscape's pieces (render/core/DESIGN.md §13): tiles^2 copies of the open periodic surface and one
    set of walls and base enclose what heightfield_solid encloses for the same tiling, and no triangle of the
    walls or base spans more than a tile (long slivers slow every ray that passes them)."""
    rng = np.random.default_rng(4)
    h, spacing, thickness = rng.normal(0.0, 0.1, (12, 12)), 0.1, 0.5
    tile = 12 * spacing
    sheet = mesh.periodic_surface(h, spacing)
    walls = mesh.tiled_closure(h, spacing, float((h - h.mean()).min()) - thickness, tiles)
    pieces = [sheet.vertices + o for o in mesh.tile_offsets(tile, tiles)] + [walls.vertices]
    counts = np.cumsum([0] + [len(v) for v in pieces])
    faces = np.concatenate([sheet.faces + counts[k] for k in range(tiles * tiles)] + [walls.faces + counts[-2]])
    welded, inverse = np.unique(np.round(np.concatenate(pieces), 9), axis=0, return_inverse=True)
    volume = mesh.manifold_volume(mesh.TriangleMesh(welded, inverse.reshape(-1)[faces]))
    assert volume == pytest.approx(mesh.manifold_volume(mesh.heightfield_solid(h, spacing, thickness, tiles)), rel=1e-6)
    corners = walls.vertices[walls.faces]
    edges = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2)
    assert edges.max() <= np.sqrt(2) * tile * (1 + 1e-9)  # a tile square's diagonal at most
    with pytest.raises(ValueError, match="odd"):
        mesh.tiled_closure(h, spacing, -1.0, 2)
