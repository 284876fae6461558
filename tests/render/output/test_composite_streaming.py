"""The streaming composite (issue 32) against the whole-stack code it replaced (composite_before_streaming):
the same encoder frames, images and EXR frames bit for bit at the same exposures; the histogram's exposures
within their stated error of the sorted ones, and the outputs within what that error moves."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from PIL import Image

from pipeline.schema.composite import CompositeConfig
from render.output import composite, figures
from render.output.exr import read_exr
from render.output.files import FrameAxis, frame_windows
from render.output.tonemap import PERCENTILE_RELATIVE_ERROR, LuminanceHistogram, luminance
from tests.render.output.composite_before_streaming import composite_outputs, old_exposures

VIDEOS = ("transient.mp4", "transient_10bit.mp4", "transient_cumulative.mp4", "light_in_flight.mp4")


def glowing_film(t_count: int, height: int, width: int, seed: int = 3) -> np.ndarray:
    """A pulse crossing a log-normal background (seven decades of luminance), with some black pixels."""
    rng = np.random.default_rng(seed)
    frames = np.exp(rng.normal(-6.0, 2.5, (t_count, height, width, 3))).astype(np.float32)
    frames[rng.random(frames.shape[:3]) < 0.2] = 0.0
    for k in range(t_count):
        column = k * width // t_count
        frames[k, height // 3 : height // 2, column : column + 3] += np.float32(2.0 + k / t_count)
    return frames


def run_streaming(tmp_path, monkeypatch, frames, steady, film, cfg):
    """The new path with a small window (three frames) and writers that keep what they are handed."""
    captured: dict = {}

    class Keep:
        def __init__(self, path, fps, crf=None, cut="web"):
            self.name, captured[path.name] = path.name, []

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return None

        def write(self, frame):
            captured[self.name].append(np.array(frame))

    def keep_streak(slab, axis, index, start, width, scale, path, *rest):
        captured[path.name] = (np.array(slab), scale)

    monkeypatch.setattr(composite, "Mp4Writer", Keep)
    monkeypatch.setattr(composite, "streak_image", keep_streak)
    monkeypatch.setattr(
        figures, "time_of_arrival_map", lambda times, path, title: captured.update({path.name: times.arrival})
    )
    window = 3 * frames[0].nbytes
    monkeypatch.setattr(composite, "frame_windows", functools.partial(frame_windows, window_bytes=window))
    written, exposures = composite.composite_film(
        frames,
        film,
        cfg,
        tmp_path,
        streaks=True,
        steady=steady,
        exr_attributes={"penitentes:config_hash": "abc"},
        metres_per_pixel=0.01,
    )
    return written, exposures, captured


CASES = [  # (curve, height, width, min height): upscaled x2 (the 10-bit cut tone-maps the enlarged frame), and not
    ("filmic", 36, 52, 64),
    ("reinhard", 70, 46, 64),
]


@pytest.mark.parametrize("curve, height, width, min_height", CASES)
def test_streaming_gives_the_whole_stack_outputs_bit_for_bit_at_the_same_exposures(
    tmp_path, monkeypatch, curve, height, width, min_height
):
    frames = glowing_film(70, height, width)  # 70 frames: the clip's exposure samples every 2nd
    steady = frames.sum(axis=0) * 0.02
    film = FrameAxis(2.0, 0.03, "bins", len(frames))
    cfg = CompositeConfig(tone_curve=curve, video_min_height=min_height, fps=24, archival_cut=True, title="t")
    written, exposures, new = run_streaming(tmp_path, monkeypatch, frames, steady, film, cfg)
    old = composite_outputs(frames, steady, film, cfg, metres_per_pixel=0.01, exposures=exposures)
    for name in VIDEOS:
        assert len(new[name]) == len(frames)
        np.testing.assert_array_equal(np.stack(new[name]), old[name], err_msg=name)
    for name in ("streak_x.png", "streak_y.png"):
        np.testing.assert_array_equal(new[name][0], old[name][0])
        assert new[name][1] == old[name][1]
    np.testing.assert_array_equal(new["time_of_arrival.png"], old["time_of_arrival.png"])
    for name in ("still.png", "light_in_flight_panel.png"):
        np.testing.assert_array_equal(np.asarray(Image.open(written[name.removesuffix(".png")])), old[name])
    import OpenImageIO as oiio

    for k in (0, 33, 69):
        path = written["exr_frames"] / f"frame_{k:04d}.exr"
        np.testing.assert_array_equal(read_exr(path), frames[k])
        spec = oiio.ImageInput.open(str(path)).spec()
        assert spec.getattribute("penitentes:exposure") == pytest.approx(exposures["clip"], rel=1e-6)
        assert spec.getattribute("penitentes:opl_m") == pytest.approx(film.centre(k))
        assert spec.getattribute("penitentes:config_hash") == "abc"


@pytest.mark.parametrize("curve, height, width, min_height", CASES)
def test_histogram_exposures_move_the_outputs_only_within_their_stated_error(
    tmp_path, monkeypatch, curve, height, width, min_height
):
    frames = glowing_film(70, height, width, seed=5)
    steady = frames.sum(axis=0) * 0.02
    film = FrameAxis(2.0, 0.03, "bins", len(frames))
    cfg = CompositeConfig(tone_curve=curve, video_min_height=min_height, fps=24, archival_cut=True)
    _, exposures, new = run_streaming(tmp_path, monkeypatch, frames, steady, film, cfg)
    sorted_ = old_exposures(frames, steady, cfg)
    for key, value in sorted_.items():
        assert abs(exposures[key] / value - 1) <= PERCENTILE_RELATIVE_ERROR, key
    old = composite_outputs(frames, steady, film, cfg, metres_per_pixel=0.01)
    # A display value y = f(s x) moves by at most |d f / d ln x| |Δs / s|; sRGB after the curves has
    # |d f / d ln x| < 2, so 8-bit codes move by at most 1 and 16-bit codes by 2 x 0.136 % of 65535 (+1).
    for name in VIDEOS:
        moved = np.abs(np.stack(new[name]).astype(np.int64) - old[name].astype(np.int64))
        bound = 1 if name != "transient_10bit.mp4" else int(2 * PERCENTILE_RELATIVE_ERROR * 65535) + 1
        assert moved.max() <= bound, name


def test_the_histogram_percentile_lies_within_its_stated_error_of_the_sorted_one():
    rng = np.random.default_rng(11)
    worst = 0.0
    for _ in range(40):
        count = int(rng.integers(1, 3000))
        rgb = np.exp(rng.normal(0, rng.uniform(0.1, 12), (count, 3))).astype(np.float32)
        rgb[rng.random(count) < 0.3] = 0
        lum = luminance(rgb)
        if not (lum > 0).any():
            continue
        histogram = LuminanceHistogram.of(rgb)
        for percentile in (50.5, 90.0, 99.5, 100.0):
            exact = float(np.percentile(lum[lum > 0], percentile))
            worst = max(worst, abs(histogram.percentile(percentile) / exact - 1))
    assert 0.3 * PERCENTILE_RELATIVE_ERROR < worst <= PERCENTILE_RELATIVE_ERROR  # the bound is tight, and holds
    assert LuminanceHistogram.of(np.zeros((4, 4, 3))).percentile(99.5) is None
    assert LuminanceHistogram.of(np.zeros((4, 4, 3))).exposure() == 1.0


def test_nan_in_a_film_is_refused_with_the_frames_named(tmp_path):
    frames = glowing_film(8, 10, 12)
    frames[6, 2, 3, 1] = np.nan
    with pytest.raises(ValueError, match="NaN or infinite"):
        composite.transient_videos(frames, FrameAxis(0.0, 0.003), CompositeConfig(), tmp_path)
    assert not list(tmp_path.glob("*.mp4"))
