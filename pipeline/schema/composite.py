"""How transient frames become videos, streak images and comparison figures."""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from common.units import SPEED_OF_LIGHT
from pipeline.schema.base import StrictModel


class CompositeConfig(StrictModel):
    """Settings of the composite stage (videos, streaks, side-by-side) and the compare stage."""

    tone_curve: Literal["reinhard", "filmic", "linear"] = Field(
        "filmic", description="Tone curve applied after exposure: reinhard, filmic (ACES fit) or linear clip [-]."
    )
    exposure_percentile: float = Field(
        99.5,
        gt=50,
        le=100,
        description="Percentile of positive luminance, over all frames, that maps to display white-ish (key 1) [%].",
    )
    per_frame_exposure: bool = Field(
        False, description="Normalise each frame on its own instead of one exposure for the clip [-]."
    )
    fps: float = Field(12.0, gt=0, le=240, description="Video frame rate [frames/s]; ignored when slow_motion is set.")
    slow_motion: float | None = Field(
        None,
        gt=0,
        description="Slow-motion factor: video seconds per second of light time [-]. Sets the frame rate from bin_width_opl.",
    )
    time_unit: Literal["ps", "ns"] = Field(
        "ps", description="Unit of every time label (videos, streak images), counted from first light [-]."
    )
    title: str | None = Field(
        None,
        max_length=120,
        description="Title burned into the videos; null: made from the site's latitude, the date and the sun [-].",
    )
    scale_bar_m: float | None = Field(
        0.5, gt=0, description="Length of the scale bar at the camera target's distance [m]; null hides it."
    )
    video_min_height: int = Field(
        480, ge=64, le=4320, description="Small renders are upscaled (nearest neighbour) to at least this height [px]."
    )
    streak_row: int | None = Field(None, ge=0, description="Image row of the x–t streak image [px]; null = middle.")
    streak_column: int | None = Field(
        None, ge=0, description="Image column of the y–t streak image [px]; null = middle."
    )
    archival_cut: bool = Field(
        False,
        description="Also write <stem>_10bit.mp4: the clip in 10-bit H.264 (High 10, yuv420p10le, BT.709 tags) for "
        "archiving and grading, beside the 8-bit web cut (render/output/LOOK.md) [-].",
    )
    denoise: bool = Field(
        False,
        description="Deliver denoised frames: Intel Open Image Denoise on each frame, guided by the first camera "
        "hit's albedo and normal, each frame keeping its raw sum (render/output/LOOK.md, *Denoised delivery*). The videos, streaks "
        "and light in flight show them; frames_denoised.npy and exr_denoised/ hold them beside the raw exr/, and "
        "raw_denoised.mp4/.png set the two side by side. With light_in_flight the still is denoised too (still.png; "
        "still_raw.png and steady_denoised.exr beside it). Comparisons, guards and tables always read the raw "
        "frames [-].",
    )
    denoise_quality: Literal["high", "balanced", "fast"] = Field(
        "high",
        description="Open Image Denoise's quality when denoise is on: high is the cleanest and takes several "
        "times as long as balanced; fast is for drafts [-].",
    )
    denoise_refine: bool = Field(
        True,
        description="When denoising, run Open Image Denoise twice on each frame: the second pass (at balanced) "
        "takes the first pass's frame as its albedo guide, since in snow the first hit's albedo is one colour "
        "everywhere and tells the network nothing about where the light lies. It lowers the error against the "
        "truth and costs one balanced pass a frame (benchmarks/crop_quality.py measures both). Leave it off where the albedo guide carries the detail (textured surfaces) "
        "(render/output/LOOK.md, *The refining pass*) [-].",
    )
    denoise_arrival_band: Literal["auto", "on", "off"] = Field(
        "auto",
        description="When denoising, keep the pixels that the direct light reaches in a frame (the arrival band, "
        "from the scene's geometry) out of that frame's denoising and give them the gain of one denoised image of "
        "the first light instead: in dense snow the first light arrives as a spike, which whole-frame denoising "
        "smears into the pixels beside it. auto: only when the raw film's band holds at least twice the light of "
        "the frame after it (2.5-4.6 in the demo's and the assets' snow, 0.95 in a thin medium, where it would "
        "hurt); on / off: always / never (render/output/LOOK.md, *The arrival band*) [-].",
    )
    exr_frames: bool = Field(
        False,
        description="Also write exr/frame_NNNN.exr, the linear frames with their OPL, time since first light, clip "
        "exposure and the render's config hash in the header [-].",
    )
    light_in_flight: bool = Field(
        False,
        description="Also write light_in_flight.mp4 (each frame's light over the dimmed steady image), "
        "light_in_flight_panel.png (four moments of it in a 2 x 2 panel of the still's size), still.png (the steady "
        "image at full size) and time_of_arrival.png [-].",
    )
    light_in_flight_dim: float = Field(
        0.25, gt=0, le=1, description="Brightness of the steady image under the light in flight [-]."
    )
    difference_vmax: float = Field(
        0.5, gt=0, description="Upper end of the relative-difference colour scale in comparisons [-]."
    )

    def frame_rate(self, bin_width_opl: float) -> float:
        """Frames per second of video: from slow_motion when set, else ``fps``."""
        if self.slow_motion is None:
            return self.fps
        light_seconds_per_frame = bin_width_opl / SPEED_OF_LIGHT
        return 1.0 / (self.slow_motion * light_seconds_per_frame)
