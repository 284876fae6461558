"""Compositing: exposure keeps brightness order, videos decode with the right size and count,
and the error metrics match hand-computed values."""

from __future__ import annotations

import numpy as np
import pytest

from common.units import PS_PER_M_OPL, SPEED_OF_LIGHT
from pipeline.schema.composite import CompositeConfig
from render import _core
from render.output.composite import side_by_side, streak_images, transient_videos
from render.output.files import FrameAxis
from render.output.metrics import per_frame_relmse, relmse, rmse
from render.output.tonemap import display_frames, luminance
from render.output.video import moov_before_mdat, probe_mp4


def pulse_frames(t_count=12, height=20, width=30, seed=0):
    """A bright spot moving right at constant speed over a faint noisy background."""
    rng = np.random.default_rng(seed)
    frames = 0.01 * rng.random((t_count, height, width, 3), dtype=np.float32)
    for k in range(t_count):
        frames[k, height // 2 - 2 : height // 2 + 2, 2 * k : 2 * k + 3] += np.array([1.0, 0.8, 0.6], dtype=np.float32)
    return frames


def test_global_exposure_keeps_brightness_order():
    base = pulse_frames()
    frames = np.stack([base[3], 2 * base[3], 0.5 * base[3]])
    for curve in ("reinhard", "filmic", "linear"):
        display, scales = display_frames(frames, curve=curve)
        assert np.all(scales == scales[0])
        mean = luminance(display.astype(np.float64)).mean(axis=(1, 2))
        assert mean[1] > mean[0] > mean[2], curve
        # And pixel by pixel: twice the energy is never displayed darker.
        assert np.all(display[1].astype(int) >= display[0].astype(int))
    # Per-frame normalisation removes the difference, as documented.
    _, scales = display_frames(frames, per_frame=True)
    assert scales[1] == pytest.approx(scales[0] / 2)


def test_videos_decode_with_the_right_frame_count_and_size(tmp_path):
    frames = pulse_frames(t_count=9, height=21, width=30)
    cfg = CompositeConfig(video_min_height=64, fps=10)
    paths = transient_videos(frames, FrameAxis(0.0, 0.003), cfg, tmp_path, metres_per_pixel=0.01)
    for key in ("video", "cumulative_video"):
        info = probe_mp4(paths[key])
        # 21 rows upscaled x4 to 84 (>= 64), 30 columns to 120; both already even.
        assert (info["codec"], info["frames"], info["width"], info["height"]) == ("h264", 9, 120, 84)


BT709_TV = {"color_primaries": 1, "color_trc": 1, "colorspace": 1, "color_range": 1}  # H.273 codes; range 1 = tv


def test_web_and_archival_cuts_carry_their_codec_pixel_format_and_bt709_tags(tmp_path):
    frames = pulse_frames(t_count=7, height=65, width=33)
    cfg = CompositeConfig(video_min_height=64, fps=24, archival_cut=True)
    paths = transient_videos(frames, FrameAxis(0.0, 0.003), cfg, tmp_path)
    web, archival = probe_mp4(paths["video"]), probe_mp4(paths["archival_video"])
    # 65 x 33 is not upscaled (>= 64 rows) but padded to 66 x 34: 4:2:0 needs even sizes.
    for info in (web, archival):
        assert (info["codec"], info["frames"], info["width"], info["height"]) == ("h264", 7, 34, 66)
        assert {k: info[k] for k in BT709_TV} == BT709_TV
    assert (web["pix_fmt"], web["profile"]) == ("yuv420p", "High")
    assert (archival["pix_fmt"], archival["profile"]) == ("yuv420p10le", "High 10")
    assert moov_before_mdat(paths["video"]) and moov_before_mdat(paths["archival_video"])


def test_light_in_flight_time_of_arrival_and_exr_frames(tmp_path):
    from render.output.composite import light_in_flight
    from render.output.exr import write_exr_frames

    frames = pulse_frames(t_count=8, height=20, width=30)
    cfg = CompositeConfig(video_min_height=64, fps=24, light_in_flight=True)
    axis = FrameAxis(3.0, 0.03, "bins", 8)
    paths = light_in_flight(frames, frames.sum(axis=0), axis, cfg, tmp_path)
    assert probe_mp4(paths["light_in_flight"])["frames"] == 8
    assert paths["time_of_arrival"].stat().st_size > 1000
    from PIL import Image

    assert Image.open(paths["still"]).size == (30, 20)
    # Below 480 rows each moment is the frame at full size, enlarged by a whole factor to >= 240 rows (12 here).
    assert Image.open(paths["light_in_flight_panel"]).size == (2 * 30 * 12, 2 * 20 * 12)
    big = pulse_frames(t_count=4, height=480, width=640)
    panel = light_in_flight(big, big.sum(axis=0), FrameAxis(3.0, 0.03, "bins", 4), cfg, tmp_path / "big")
    assert Image.open(panel["light_in_flight_panel"]).size == Image.open(panel["still"]).size == (640, 480)
    written = write_exr_frames(
        tmp_path / "exr", frames, axis, {"penitentes:exposure": 2.5, "penitentes:config_hash": "abc"}
    )
    import OpenImageIO as oiio

    spec = oiio.ImageInput.open(str(written[3])).spec()
    assert spec.getattribute("penitentes:opl_m") == pytest.approx(3.0 + 3.5 * 0.03)
    assert spec.getattribute("penitentes:time_ns_since_first_light") == pytest.approx(3.5 * 0.03 / SPEED_OF_LIGHT * 1e9)
    assert spec.getattribute("penitentes:exposure") == pytest.approx(2.5)
    assert spec.getattribute("penitentes:config_hash") == "abc"


def test_slow_motion_sets_the_frame_rate_and_absurd_rates_are_refused(tmp_path):
    film = FrameAxis(0.0, 0.003)
    cfg = CompositeConfig(slow_motion=1e10)
    assert cfg.frame_rate(0.003) == pytest.approx(1 / (1e10 * 0.003 / SPEED_OF_LIGHT))
    with pytest.raises(ValueError, match="composite.slow_motion"):
        transient_videos(pulse_frames(), film, CompositeConfig(slow_motion=1.0), tmp_path)


def test_streak_images_and_side_by_side(tmp_path):
    frames = pulse_frames()
    cfg = CompositeConfig(video_min_height=64)
    paths = streak_images(frames, FrameAxis(0.0, 0.003), cfg, tmp_path)
    assert paths["streak_x"].stat().st_size > 1000 and paths["streak_y"].stat().st_size > 1000
    with pytest.raises(ValueError, match="composite.streak_row=99"):
        streak_images(frames, FrameAxis(0.0, 0.003), CompositeConfig(streak_row=99), tmp_path)
    out = side_by_side(frames, frames * 1.1, ("ours", "reference"), FrameAxis(0.0, 0.003), cfg, tmp_path)
    assert probe_mp4(out["side_by_side_video"])["frames"] == len(frames)
    assert out["side_by_side_still"].stat().st_size > 1000


def test_side_by_side_shrinks_wide_films(tmp_path, monkeypatch):
    """A film wider than the panel width is box-averaged for the side-by-side clip by the smallest factor that
    divides both sides: 1080p by 2, 4K by 3 (1280 x 720 panels), the demo's 128 x 96 not at all; a shrunk
    panel is not enlarged again for small films' sake."""
    from render.output import composite

    assert [composite.panel_factor(h, w) for h, w in ((1080, 1920), (2160, 3840), (96, 128), (1081, 1921))] == [
        2,
        3,
        1,
        1,
    ]
    # video_min_height 128 would enlarge a 40-row panel to 80 rows; a shrunk panel is left as it is.
    frames, cfg, film = pulse_frames(height=80, width=120), CompositeConfig(video_min_height=128), FrameAxis(0.0, 0.003)
    full = side_by_side(frames, frames * 1.1, ("a", "b"), film, cfg, tmp_path / "full")
    monkeypatch.setattr(composite, "SIDE_BY_SIDE_PANEL_WIDTH", 60)
    shrunk = side_by_side(frames, frames * 1.1, ("a", "b"), film, cfg, tmp_path / "shrunk")
    before, after = probe_mp4(full["side_by_side_video"]), probe_mp4(shrunk["side_by_side_video"])
    assert before["frames"] == after["frames"] == len(frames)
    assert (after["width"], after["height"]) == (before["width"] // 2, before["height"] // 2), (before, after)


def test_error_metrics_match_hand_computed_values():
    reference = np.array([[1.0, 0.0], [2.0, 0.1]])
    estimate = np.array([[1.5, 0.1], [1.0, 0.1]])
    # relMSE: (0.25/1.01 + 0.01/0.01 + 1/4.01 + 0/0.02) / 4
    expected = (0.25 / 1.01 + 0.01 / 0.01 + 1.0 / 4.01 + 0.0) / 4
    assert relmse(estimate, reference) == pytest.approx(expected, rel=1e-12)
    assert rmse(estimate, reference) == pytest.approx(np.sqrt((0.25 + 0.01 + 1.0 + 0.0) / 4), rel=1e-12)
    frames = np.stack([reference, estimate])
    np.testing.assert_allclose(per_frame_relmse(frames, np.stack([reference, reference])), [0.0, expected])
    with pytest.raises(ValueError, match="shapes differ"):
        relmse(estimate, reference[:1])
    with pytest.raises(ValueError, match="NaN"):
        rmse(np.full((2, 2), np.nan), reference)


def test_picosecond_conversion_uses_the_exact_speed_of_light():
    assert PS_PER_M_OPL == pytest.approx(3335.640952, rel=1e-9)
    assert (SPEED_OF_LIGHT, PS_PER_M_OPL) == (_core.SPEED_OF_LIGHT, _core.PS_PER_M_OPL)  # one constant, two languages
    assert 0.003 * PS_PER_M_OPL == pytest.approx(10.007, abs=1e-3)


def test_streak_time_axis_counts_from_first_light_in_the_configured_unit(tmp_path, monkeypatch):
    from render.output import figures

    made = []
    subplots = figures.plt.subplots

    def keep(*args, **kwargs):
        fig, ax = subplots(*args, **kwargs)
        made.append(ax)
        return fig, ax

    monkeypatch.setattr(figures.plt, "subplots", keep)
    frames = np.ones((10, 6, 8, 3), np.float32)
    streak_images(frames, FrameAxis(25.0, 0.3), CompositeConfig(time_unit="ns"), tmp_path)
    for ax in made:  # the window opens at OPL 25 m: time 0; 10 bins of 0.3 m last 10.007 ns
        assert ax.get_ylim() == pytest.approx((0.0, 3.0 / SPEED_OF_LIGHT * 1e9), rel=1e-9)
        assert ax.get_ylabel().startswith("time since first light (ns)")
