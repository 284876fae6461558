"""The denoised delivery (render/output/LOOK.md, *Denoised delivery*) on the lit block of block_scene: guides from the scene's
own geometry, denoised frames that keep each raw frame's sum and come closer to a 16x longer render than the
raw frames do, raw and denoised EXRs that say which is which, and raw frames that nothing touches."""

from __future__ import annotations

import csv
import hashlib
import json

import numpy as np
import OpenImageIO as oiio
import pytest
import yaml
from block_scene import block_config
from PIL import Image

from pipeline.config import load_config
from pipeline.runner import run_stages
from pipeline.stages import STAGES
from render.output.exr import read_exr
from render.output.guides import guide_buffers
from render.output.metrics import per_frame_relmse, relmse

pytestmark = pytest.mark.mitsuba


def _run(tmp_path, name: str, iterations: int, seed: int, composite: dict | None = None):
    text = block_config(
        tmp_path / "runs",
        name=name,
        seed=seed,
        reference={"spp": 16},
        render={"iterations": iterations, "snapshot_every": iterations, "light_paths_per_iteration": 6000},
        width=48,
        height=32,
    )
    data = yaml.safe_load(text)
    data["composite"] = {**data["composite"], **(composite or {})}
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    # The composite stage waits for the reference (it sets ours beside mitransient when one exists).
    stages = ("scene", "reference", "render", "composite", "compare") if composite else ("scene", "render")
    results = run_stages(load_config(path), STAGES, only=stages, quiet=True)
    assert all(r.status == "ran" for r in results if r.name in stages), results
    return tmp_path / "runs" / name


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    tmp_path = tmp_path_factory.mktemp("denoise")
    noisy = _run(tmp_path, "noisy", 4, seed=5, composite={"denoise": True, "exr_frames": True, "light_in_flight": True})
    long = _run(tmp_path, "long", 64, seed=6)
    return noisy, long


def test_the_comparison_rows_do_not_see_the_denoiser(runs, tmp_path):
    """The same run with denoising off gives the same comparison rows (errors, means, agreement), the timing and
    memory columns aside."""
    noisy, _ = runs
    plain = _run(tmp_path, "noisy", 4, seed=5, composite={"denoise": False, "exr_frames": True})

    def rows(run):
        with open(run / "compare" / "comparison.csv", newline="") as f:
            return [
                {k: v for k, v in row.items() if k not in ("seconds", "peak_memory_mib")} for row in csv.DictReader(f)
            ]

    compared = rows(noisy)
    assert any(row["relmse"] not in ("", "–") for row in compared), compared
    assert rows(plain) == compared
    assert not (plain / "composite" / "frames_denoised.npy").exists()


def test_guides_are_the_first_hit_of_the_scene(runs):
    """Where a camera ray meets the block the albedo guide is the medium's diffuse albedo r_d (optics.json) and
    the normal a unit vector facing the camera; the top face's pixels see (0, 0, 1); rays past the block
    see nothing (zero albedo and normal)."""
    noisy, _ = runs
    guides = guide_buffers(noisy / "scene")
    r_d = np.array(json.loads((noisy / "scene" / "optics.json").read_text())["snow"]["derived"]["diffuse_albedo"])
    length = np.linalg.norm(guides.normal, axis=2)
    inside = length > 0.999  # every sub-pixel ray hit the same face
    assert inside.sum() > 100 and (length < 1e-6).sum() > 20
    np.testing.assert_allclose(guides.albedo[inside], np.broadcast_to(r_d, guides.albedo[inside].shape), rtol=1e-5)
    np.testing.assert_array_equal(guides.albedo[length < 1e-6], 0.0)
    top = inside & (guides.normal[..., 2] > 0.99)
    assert top.sum() > 50
    np.testing.assert_allclose(guides.normal[top], np.broadcast_to([0, 0, 1], guides.normal[top].shape), atol=1e-5)


def test_arrival_bins_are_where_the_first_light_is(runs):
    """The guides' arrival bins (the sun's direct light over each pixel's corners) against the 16x longer render:
    pixels that see no surface have none; on the block no light comes before a pixel's first arrival frame
    (nothing is faster than the direct path), and its arrival frames hold light."""
    noisy, long = runs
    guides = guide_buffers(noisy / "scene")
    frames = np.load(long / "render" / "frames.npy")
    bins = guides.arrival_bins
    assert bins is not None and bins.shape == (1, 2, *frames.shape[1:3])
    first, last = bins[0]
    # Pixels whose 16 guide rays and whose neighbours' all miss: their corners miss too.
    missed = np.pad(np.linalg.norm(guides.normal, axis=2) < 1e-6, 1, constant_values=True)
    empty = np.all([np.roll(np.roll(missed, dy, 0), dx, 1) for dy in (-1, 0, 1) for dx in (-1, 0, 1)], axis=0)
    empty = empty[1:-1, 1:-1]
    assert empty.sum() > 20 and np.all(first[empty] == -1) and np.all(last[empty] == -1)
    seen = (first >= 0) & (last < frames.shape[0])
    assert seen.sum() > 100 and np.all(last[seen] >= first[seen])
    light = frames.sum(axis=3)  # (T, H, W)
    k = np.arange(frames.shape[0])[:, None, None]
    early = (k < first[None]) & seen[None]
    assert float(light[early].sum()) == 0.0
    in_band = (k >= first[None]) & (k <= last[None]) & seen[None]
    rows, cols = np.nonzero(seen)
    held = in_band.reshape(frames.shape[0], -1)[:, rows * frames.shape[2] + cols]
    lit_in_band = (light.reshape(frames.shape[0], -1)[:, rows * frames.shape[2] + cols] * held).sum(axis=0) > 0
    assert lit_in_band.mean() > 0.9, lit_in_band.mean()


def test_denoised_frames_keep_their_sums_and_approach_a_longer_render(runs):
    """Each denoised frame keeps its raw frame's sum per channel (to float rounding); over the frames holding
    more than 1 % of the energy, the denoised frames' relMSE against a 16x longer render (another seed) is below
    a third of the raw frames' (measured 0.22 of it; the longer render's own noise is part of what remains)."""
    noisy, long = runs
    raw = np.load(noisy / "render" / "frames.npy")
    delivered = np.load(noisy / "composite" / "frames_denoised.npy")
    reference = np.load(long / "render" / "frames.npy")
    assert delivered.shape == raw.shape and np.all(np.isfinite(delivered)) and delivered.min() >= 0
    np.testing.assert_allclose(delivered.sum(axis=(1, 2)), raw.sum(axis=(1, 2)), rtol=1e-4, atol=1e-9)
    energy = reference.sum(axis=(1, 2, 3))
    held = energy > 0.01 * energy.sum()
    raw_error = per_frame_relmse(raw, reference)[held]
    denoised_error = per_frame_relmse(delivered, reference)[held]
    assert held.sum() >= 4
    assert denoised_error.mean() < raw_error.mean() / 3, (denoised_error, raw_error)


def test_the_still_is_denoised_and_keeps_its_sum(runs):
    """With light in flight on, the still (the poster's main image) is the denoised steady image: it keeps the raw
    steady image's sum per channel and comes closer to the 16x longer render's steady image than the raw one
    does (measured 0.41 of its relMSE on this 48 x 32 film, where edges are a large share of the pixels); the raw still and the denoised EXR are written beside it, and the
    render's steady image is untouched."""
    noisy, long = runs
    raw = np.load(noisy / "render" / "steady.npy")
    reference = np.load(long / "render" / "steady.npy")
    delivered = read_exr(noisy / "composite" / "steady_denoised.exr")
    assert delivered.shape == raw.shape and np.all(np.isfinite(delivered)) and delivered.min() >= 0
    np.testing.assert_allclose(delivered.sum(axis=(0, 1)), raw.sum(axis=(0, 1)), rtol=1e-4)
    assert relmse(delivered, reference) < relmse(raw, reference) / 2, (
        relmse(delivered, reference),
        relmse(raw, reference),
    )
    image = oiio.ImageInput.open(str(noisy / "composite" / "steady_denoised.exr"))
    assert image.spec().getattribute("penitentes:frames") == "denoised"
    image.close()
    for name in ("still.png", "still_raw.png"):
        assert Image.open(noisy / "composite" / name).size == (raw.shape[1], raw.shape[0])
    summary = json.loads((noisy / "composite" / "manifest.json").read_text())["summary"]
    assert summary["denoise"]["still_sum_change"] < 1e-4
    # The block's thin medium sends its first light back over several frames, not as a spike: the band stays in.
    band = summary["denoise"]["arrival_band"]
    assert band["kept_apart"] is False and 0.5 < band["sharpness"] < 2.0, band
    assert {"still_raw.png", "steady_denoised.exr"} <= set(summary["files"])


def test_raw_frames_stay_raw_and_the_headers_say_which(runs):
    """The composite writes beside the render, never over it: the render's frames.npy is what the compare stage
    and every table read, and its hash is in the render's manifest. The raw and denoised EXR frames carry
    penitentes:frames = raw / denoised; the side-by-side of the two is written."""
    noisy, _ = runs
    manifest = json.loads((noisy / "render" / "manifest.json").read_text())
    digest = hashlib.sha256((noisy / "render" / "frames.npy").read_bytes()).hexdigest()
    assert manifest["outputs"]["frames.npy"]["sha256"] == digest
    for folder, kind in (("exr", "raw"), ("exr_denoised", "denoised")):
        image = oiio.ImageInput.open(str(noisy / "composite" / folder / "frame_0000.exr"))
        assert image.spec().getattribute("penitentes:frames") == kind
        image.close()
    summary = json.loads((noisy / "composite" / "manifest.json").read_text())["summary"]
    listed = set(summary["files"])
    assert {"raw_denoised.mp4", "denoise_guides.png", "transient.mp4", "reference_transient.mp4"} <= listed, listed
    assert summary["denoise"]["largest_frame_sum_change"] < 1e-4
