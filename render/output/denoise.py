"""Denoised delivery frames (render/output/LOOK.md, *Denoised delivery*): Intel Open Image Denoise (``pyoidn``, CPU) on each
transient frame, guided by the albedo and normal of the first camera hit (``Guides``, which
render.output.guides traces from the scene's own triangles: noise-free and the same for every frame).

Denoised frames are for people to look at. Comparisons, guards, tables and the sweep summary read the raw
frames; nothing here writes over them.
"""

from __future__ import annotations

import math
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy.ndimage import gaussian_filter, zoom

from common.atomic import atomic_path
from render.output.files import frame_windows


@dataclass(frozen=True)
class Guides:
    """First-hit albedo [0, 1] and world-space unit normal (facing the camera) per pixel, (H, W, 3) float32; for a
    transient film, ``arrival_bins`` (lights, 2, H, W) int32: the first and last frame that each light's direct
    arrival reaches within each pixel (-1: none; render.output.guides.arrival_bins), which denoise_film keeps
    apart from the rest of each frame (render/output/LOOK.md, *The arrival band*)."""

    albedo: np.ndarray
    normal: np.ndarray
    arrival_bins: np.ndarray | None = None

    def band(self, frame: int) -> np.ndarray | None:
        """(H, W) bool: the pixels whose direct arrival falls in ``frame``; None without arrival bins."""
        if self.arrival_bins is None:
            return None
        first, last = self.arrival_bins[:, 0], self.arrival_bins[:, 1]
        return np.any((first <= frame) & (frame <= last) & (first >= 0), axis=0)


QUALITIES = ("high", "balanced", "fast")  # Open Image Denoise's quality levels, as composite.denoise_quality names them

# The refining pass (render/output/LOOK.md, *The refining pass*): the first pass's output, scaled so that this
# percentile of its positive luminance is 1 and clipped to [0, 1], is the albedo guide of a second pass over the
# same input, at this quality. In snow the first hit's albedo is one colour everywhere and tells the network
# nothing; the first pass's output tells it where the frame's light lies. On the demo's crop, balanced here did
# better than high (0.089 / 0.086 of raw against 0.093 / 0.090, seeds 11 / 21, 64 iterations) at a third of
# the time.
REFINE_GUIDE_PERCENTILE = 99.5
REFINE_QUALITY = "balanced"


class Denoiser:
    """OIDN's ray-tracing filter (CPU, HDR mode, clean guides) set up once for the frames of a film:
    ``with Denoiser(guides, quality) as denoiser: denoised = denoiser(frame)``.

    One device and one filter bound to the guides and to a colour and an output frame that each call fills and
    reads. On exit both are released, and with them OIDN's working memory, about 1.3 GB for a 1080p frame:
    ``pyoidn.denoise`` keeps its filter, and that memory, for the rest of the process, which put it under the
    video encoders that run after denoising. The filter and its inputs are the ones ``pyoidn.denoise`` sets,
    so the frames are the same bit for bit.

    With ``refine``, a second filter (REFINE_QUALITY) reads the same colour and normal with an albedo guide of
    its own, which each call fills from the first filter's output (render/output/LOOK.md, *The refining
    pass*)."""

    def __init__(self, guides: Guides, quality: str = "high", refine: bool = False) -> None:
        if quality not in QUALITIES:
            raise ValueError(f"denoise quality must be one of {', '.join(QUALITIES)}, got {quality!r}")
        self.guides, self.quality = guides, quality
        height, width = guides.albedo.shape[:2]
        # OIDN reads these through pointers set once (shared images): they live as long as the filter.
        self.color = np.zeros((height, width, 3), np.float32)
        self.output = np.zeros((height, width, 3), np.float32)
        self.albedo = np.ascontiguousarray(guides.albedo, np.float32)
        self.normal = np.ascontiguousarray(guides.normal, np.float32)
        # The refining pass's own albedo guide and output, only with ``refine`` (never the guides' arrays, which
        # the first filter reads): two more frames, 100 MB each at 4K.
        self.refine_buffers = (
            (np.zeros((height, width, 3), np.float32), np.zeros((height, width, 3), np.float32)) if refine else None
        )
        self._release = ExitStack()
        self._device: Any = None
        self._filter: Any = None
        self._refine_filter: Any = None

    def __enter__(self) -> Denoiser:
        import pyoidn

        try:
            device = pyoidn.Device()
            self._release.callback(device.release)
            device.commit()
            self._check(device, "device creation")
            flt = self._rt_filter(pyoidn, device, self.albedo, self.output, self.quality)
            if self.refine_buffers is not None:
                self._refine_filter = self._rt_filter(pyoidn, device, *self.refine_buffers, REFINE_QUALITY)
            self._check(device, "filter set-up")
        except BaseException:
            self._release.close()
            self._refine_filter = None
            raise
        self._device, self._filter = device, flt
        return self

    def _rt_filter(self, pyoidn: Any, device: Any, albedo: np.ndarray, output: np.ndarray, quality: str) -> Any:
        """A ray-tracing filter on this denoiser's colour and normal with the given albedo guide and output,
        released on exit before its device."""
        flt = pyoidn.Filter(device, pyoidn.OIDN_FILTER_TYPE_RT)
        self._release.callback(flt.release)
        for name, image in (
            (pyoidn.OIDN_IMAGE_COLOR, self.color),
            (pyoidn.OIDN_IMAGE_ALBEDO, albedo),
            (pyoidn.OIDN_IMAGE_NORMAL, self.normal),
            (pyoidn.OIDN_IMAGE_OUTPUT, output),
        ):
            flt.set_image(name, image, pyoidn.OIDN_FORMAT_FLOAT3)
        flt.set_bool("hdr", True)
        flt.set_bool("cleanAux", True)
        flt.set_quality(getattr(pyoidn, f"OIDN_QUALITY_{quality.upper()}"))
        flt.commit()
        return flt

    def __exit__(self, *exc: object) -> None:
        self._device = self._filter = self._refine_filter = None
        self._release.close()

    @staticmethod
    def _check(device: Any, operation: str) -> None:
        error = device.get_error()
        if error is not None:
            raise RuntimeError(f"Open Image Denoise: {operation} failed: {error}")

    def __call__(self, frame: np.ndarray) -> np.ndarray:
        """One (H, W, 3) linear frame through the filter, brought to the raw frame's light region by region
        (``_at_raw_light``), then scaled per channel to the raw frame's sum. The network moves light between
        pixels but was not trained to keep a frame's energy (on the demo at 64 iterations it lost 1-4 % of late
        frames' light); the raw frame's sum is an unbiased estimate of it with far less noise than any pixel, so
        the denoised frame keeps it. An all-black frame stays black without a call. With ``refine`` that frame
        guides a second pass, whose output is brought to the raw light the same way."""
        if self._filter is None:
            raise RuntimeError("Denoiser called outside its with block")
        if frame.shape != self.color.shape:
            raise ValueError(f"a frame of shape {frame.shape} does not match the guides' {self.color.shape}")
        if not np.any(frame):
            return np.zeros_like(frame, dtype=np.float32)
        np.maximum(frame, 0.0, out=self.color)
        first = self._pass(self._filter, self.output, frame)
        if self.refine_buffers is None:
            return first
        guide, output = self.refine_buffers
        _refine_guide(first, guide)
        return self._pass(self._refine_filter, output, frame)

    def _pass(self, flt: Any, output: np.ndarray, frame: np.ndarray) -> np.ndarray:
        """One run of ``flt`` on the colour buffer, its output kept at the raw frame's light and sum."""
        flt.execute()
        self._check(self._device, "filter execution")
        # One float64 copy of the network's output, clipped and scaled in place: a 1080p frame is 50 MB in float64,
        # and each whole-frame temporary would be another.
        out = np.array(output, np.float64)
        np.maximum(out, 0.0, out=out)
        _at_raw_light(out, self.color)
        return _at_raw_sum(out, frame)


def _refine_guide(first: np.ndarray, guide: np.ndarray) -> None:
    """Fill ``guide`` (H, W, 3 float32, in place) with the first pass's frame scaled so that the
    REFINE_GUIDE_PERCENTILE of its positive luminance (the channels' mean) is 1, clipped to [0, 1]: an albedo
    guide in the range the network was trained on. All zero when the frame has no light."""
    luminance = first.mean(axis=2)
    lit = luminance[luminance > 0]
    if lit.size == 0:
        guide[...] = 0.0
        return
    level = float(np.percentile(lit, REFINE_GUIDE_PERCENTILE))
    # In the guide's own buffer: no frame-sized temporary (100 MB at 4K) for every frame.
    np.divide(first, level, out=guide, casting="same_kind")
    np.clip(guide, 0.0, 1.0, out=guide)


# The scale (Gaussian standard deviation, pixels) over which a denoised frame keeps the raw frame's light
# (render/output/LOOK.md, *Local light*): the raw light summed over some 2 pi 32^2 ~ 6400 pixels has a few
# per cent of noise in the full video's late glow, where one raw pixel has more than 100 %. The light is summed
# in blocks of LOCAL_LIGHT_BLOCK pixels a side first, and the ratio brought back bilinearly: at 1080p that is
# 0.15 s a frame, against 0.5 s for the same Gaussian over every pixel.
LOCAL_LIGHT_SIGMA = 32.0
LOCAL_LIGHT_BLOCK = 4


def _block_light(image: np.ndarray) -> np.ndarray:
    """The light of (H, W, 3) summed over its channels and over blocks of LOCAL_LIGHT_BLOCK pixels (the last row
    and column of blocks may be narrower), as float64."""
    light = image[..., 0].astype(np.float64) + image[..., 1] + image[..., 2]
    starts = [np.arange(0, n, LOCAL_LIGHT_BLOCK) for n in light.shape]
    return np.add.reduceat(np.add.reduceat(light, starts[0], axis=0), starts[1], axis=1)


def _at_raw_light(out: np.ndarray, raw: np.ndarray) -> None:
    """Scale ``out`` (H, W, 3 float64, in place) by G(raw) / G(out) over the summed channels, G a Gaussian of
    LOCAL_LIGHT_SIGMA pixels: the network keeps no region's light, and where one region's raw light lies in a few
    rare samples and another's is dense, it drops the rare ones and the frame's sum then lent their light to
    the dense region (the full video's late frames: 0.60-0.90 of the raw light in the foreground, 1.07-1.27 on
    the horizon). Light the network put where the raw frame has none within a few sigma goes; where the network
    left none, nothing can be scaled and the frame's sum takes it."""
    sigma = LOCAL_LIGHT_SIGMA / LOCAL_LIGHT_BLOCK
    coarse_raw = gaussian_filter(_block_light(raw), sigma, truncate=3.0)
    coarse_out = gaussian_filter(_block_light(out), sigma, truncate=3.0)
    floor = 1e-12 * float(coarse_raw.max())
    ratio = np.divide(coarse_raw, coarse_out, out=np.ones_like(coarse_out), where=coarse_out > floor)
    height, width = out.shape[:2]
    out *= zoom(ratio, LOCAL_LIGHT_BLOCK, order=1, grid_mode=True, mode="nearest")[:height, :width, None]


def _at_raw_sum(out: np.ndarray, frame: np.ndarray) -> np.ndarray:
    """``out`` (float64, scaled in place) kept at the raw frame's sum per channel, as float32."""
    raw_sum, out_sum = np.asarray(frame, np.float64).sum(axis=(0, 1)), out.sum(axis=(0, 1))
    scale = np.divide(raw_sum, out_sum, out=np.ones(3), where=out_sum > 0)
    out *= np.maximum(scale, 0.0)
    return out.astype(np.float32)


def denoise_frame(frame: np.ndarray, guides: Guides, quality: str = "high", refine: bool = False) -> np.ndarray:
    """One (H, W, 3) linear frame denoised and kept at its raw sum (``Denoiser``, set up for this frame alone)."""
    with Denoiser(guides, quality, refine) as denoiser:
        return denoiser(frame)


# The arrival band is kept apart when the first light is a spike: over the band pixels, their light in their
# arrival frames at least this many times their light in the frame after (render/output/LOOK.md, *The arrival
# band*; measured 2.5-4.6 in the demo's and the assets' snow, 0.95 in a thin medium, where it would hurt).
SHARP_ARRIVAL = 2.0
ARRIVAL_BAND_MODES = ("auto", "on", "off")


@dataclass(frozen=True)
class ArrivalBand:
    """What denoise_film did with the arrival band: ``sharpness`` (the band pixels' light in their arrival frames
    over theirs in the frame after, from the raw film), whether the band was kept apart (``used``), and the
    prompt image's gain (H, W, 3) when it was."""

    sharpness: float
    used: bool
    gain: np.ndarray | None


@dataclass(frozen=True)
class DenoisedFilm:
    """A denoised stack (memory-mapped) with what one pass over it measured: the largest relative change of a lit
    frame's sum, and the flicker (TemporalRoughness) of the raw and the denoised frames."""

    frames: np.ndarray
    largest_frame_sum_change: float
    temporal_roughness_raw: float
    temporal_roughness_denoised: float
    arrival: ArrivalBand | None = None


def denoise_film(
    frames: np.ndarray,
    guides: Guides,
    path: Path,
    quality: str = "high",
    progress: bool = True,
    arrival_band: str = "auto",
    refine: bool = False,
) -> DenoisedFilm:
    """Denoise a (T, H, W, 3) stack (in memory or memory-mapped) frame by frame into ``path`` (.npy), written to a
    temporary file and renamed when complete, measuring the frames as they pass. With arrival bins in the guides
    and ``arrival_band`` "auto" or "on", a first pass over the film sums the prompt image and decides whether the
    band is kept apart (``_arrival_band``); the frames are then denoised in a second.

    The film is read a window at a time (``files.frame_windows``, which drops a memory-mapped film's pages after
    each window) and the denoised frames are appended to the file as they are made, so the pass holds a window
    and a few frames, not the film: pages of a memory-mapped input, and of a memory-mapped output written in
    place, stay in the process's resident size until unmapped, and a full 1080p video's 6 GB film counted
    twice that way (render/output/LOOK.md, "Memory")."""
    from tqdm import tqdm

    path = Path(path)
    if frames.shape[1:3] != guides.albedo.shape[:2]:
        raise ValueError(
            f"frames are {frames.shape[2]}x{frames.shape[1]} pixels but the scene's camera is "
            f"{guides.albedo.shape[1]}x{guides.albedo.shape[0]}; run the scene and render stages again"
        )
    shape = tuple(int(n) for n in frames.shape)
    # The header np.save and np.lib.format.open_memmap write for this dtype and shape (format 1.0), so the
    # file's bytes are theirs.
    header = {"descr": np.lib.format.dtype_to_descr(np.dtype(np.float32)), "fortran_order": False, "shape": shape}
    raw_flicker, denoised_flicker, largest_change = TemporalRoughness(), TemporalRoughness(), 0.0
    with (
        Denoiser(guides, quality, refine) as denoiser,
        atomic_path(path) as temporary,
        open(temporary, "wb") as out,
        tqdm(total=shape[0], desc="denoise", unit="frame", disable=not progress, leave=False) as bar,
    ):
        arrival = _arrival_band(frames, guides, denoiser, arrival_band)
        gain = arrival.gain if arrival is not None else None
        np.lib.format.write_array_header_1_0(out, header)
        for first, window in frame_windows(frames):
            for index, frame in enumerate(window, first):
                frame = np.asarray(frame, np.float32)
                denoised = _denoise_with_band(frame, guides.band(index), gain, denoiser)
                out.write(denoised.data)
                raw_sum = float(np.sum(frame, dtype=np.float64))
                if raw_sum > 0:
                    change = abs(float(np.sum(denoised, dtype=np.float64)) / raw_sum - 1.0)
                    largest_change = max(largest_change, change)
                raw_flicker.add(frame)
                denoised_flicker.add(denoised)
                bar.update()
    return DenoisedFilm(
        np.load(path, mmap_mode="r"), largest_change, raw_flicker.value, denoised_flicker.value, arrival
    )


def _arrival_band(frames: np.ndarray, guides: Guides, denoiser: Denoiser, mode: str) -> ArrivalBand | None:
    """The arrival band of a film (None without arrival bins or with mode "off"): one pass over the raw frames
    sums the prompt image P (each pixel's light in the frames its direct arrival falls in) and the same pixels'
    light in the frame after; with mode "on", or "auto" and a sharpness of at least SHARP_ARRIVAL, P is denoised
    and the gain is the denoised P over P (0 where P is 0).

    P is one image of the first light: each band pixel's value in its arrival frames, which a frame's own
    denoising smears into the pixels beside it. Denoised on its own it is as clean as a steady image, and each
    band pixel keeps its raw split between its arrival frames (render/output/LOOK.md, *The arrival band*)."""
    if mode not in ARRIVAL_BAND_MODES:
        raise ValueError(f"arrival_band must be one of {', '.join(ARRIVAL_BAND_MODES)}, got {mode!r}")
    if guides.arrival_bins is None or mode == "off":
        return None
    prompt = np.zeros(guides.albedo.shape, np.float64)
    after = 0.0
    seen = guides.arrival_bins[:, 0] >= 0
    for first, window in frame_windows(frames):
        for index, frame in enumerate(window, first):
            band = guides.band(index)
            following = np.any(seen & (guides.arrival_bins[:, 1] == index - 1), axis=0)
            if band is not None and band.any():
                prompt[band] += np.asarray(frame, np.float64)[band]
            if following.any():
                after += float(np.asarray(frame, np.float64)[following].sum())
    total = float(prompt.sum())
    sharpness = total / after if after > 0 else (math.inf if total > 0 else 0.0)
    used = total > 0 and (mode == "on" or sharpness >= SHARP_ARRIVAL)
    if not used:
        return ArrivalBand(sharpness, False, None)
    clean = denoiser(prompt.astype(np.float32)).astype(np.float64)
    return ArrivalBand(sharpness, True, np.divide(clean, prompt, out=np.zeros_like(prompt), where=prompt > 0))


def _denoise_with_band(frame: np.ndarray, band: np.ndarray | None, gain: np.ndarray | None, denoiser: Denoiser):
    """One frame: without a band, through the denoiser as it is. With one, the band pixels leave the denoiser's
    input (they go back scaled by the prompt image's gain) and the rest is denoised alone; the frame is then kept
    at its raw sum per channel, as every denoised frame is."""
    if band is None or gain is None or not band.any():
        return denoiser(frame)
    rest = frame.copy()
    rest[band] = 0.0
    out = denoiser(rest).astype(np.float64)
    out[band] += np.asarray(frame, np.float64)[band] * gain[band]
    return _at_raw_sum(out, frame)


def save_guides(guides: Guides, path: Path) -> Path:
    """``path`` (PNG): the albedo guide beside the normal guide (n/2 + 1/2, grey where nothing is hit), each at
    least 256 pixels wide."""
    from PIL import Image

    normal = np.where(np.any(guides.normal != 0, axis=2, keepdims=True), 0.5 * guides.normal + 0.5, 0.5)
    panel = np.concatenate([np.clip(guides.albedo, 0.0, 1.0), np.clip(normal, 0.0, 1.0)], axis=1)
    image = Image.fromarray((panel * 255 + 0.5).astype(np.uint8))
    zoom = max(1, -(-256 // guides.albedo.shape[1]))
    image = image.resize((image.width * zoom, image.height * zoom), Image.Resampling.NEAREST)
    with atomic_path(path) as temporary:
        image.save(temporary, format="PNG")
    return Path(path)


class TemporalRoughness:
    """Frame-to-frame flicker of a stack fed one frame at a time [-]: the summed |second difference in time| of
    every pixel over the summed signal, sum |f[k+1] - 2 f[k] + f[k-1]| / sum |f|. Noise that changes from frame
    to frame raises it; a smooth wavefront moving through the frames keeps it low."""

    def __init__(self) -> None:
        self.rough, self.total = 0.0, 0.0
        self.recent: list[np.ndarray] = []  # the two frames before the next one, in their own precision
        self._work: np.ndarray | None = None  # one float64 frame that every sum is taken over

    def add(self, frame: np.ndarray) -> None:
        # The sums run over a C-ordered float64 frame, and the second difference is computed in float64 with
        # the same operations in the same order, in place: the values are those of converting every frame to
        # float64 first (converting float32 is exact), with one float64 frame held instead of three and the
        # temporaries of the expression.
        frame = np.asarray(frame)
        if self._work is None or self._work.shape != frame.shape:
            self._work = np.empty(frame.shape, np.float64)
        work = self._work
        np.abs(frame, out=work)
        self.total += float(work.sum())
        if len(self.recent) == 2:
            np.multiply(self.recent[1], 2.0, out=work, dtype=np.float64)
            np.subtract(frame, work, out=work, dtype=np.float64)
            np.add(work, self.recent[0], out=work, dtype=np.float64)
            np.abs(work, out=work)
            self.rough += float(work.sum())
        self.recent = [*self.recent[-1:], np.array(frame)]

    @property
    def value(self) -> float:
        return self.rough / self.total if self.total > 0 else 0.0
