"""Issue 32's acceptance figures for the composite of a render folder: the stage's time and own peak memory
(common/memory.py), and the clip exposure from the histogram against the old sort of every sampled pixel.
With ``--denoise`` the film is denoised first (``composite.denoise_quality``), as the stage does with
``composite.denoise``, and the denoised frames are composited; the denoising pass is timed and measured apart.

    python benchmarks/bench_composite.py runs/video/render configs/assets/video.yaml
    python benchmarks/bench_composite.py --synthetic 24x1080x1920 configs/assets/video.yaml
    python benchmarks/bench_composite.py --denoise --synthetic 48x1080x1920 configs/assets/video.yaml

The sort is the old computation (issue 32: a float64 luminance of every sampled pixel), so this script,
unlike the stage, needs memory in proportion to the sampled frames (about 1 GiB a 64-frame sample at 1080p).
Prints the figures and writes them to benchmarks/results/bench_composite_<config>[_denoise].md and .csv (a
synthetic film's to results/local/).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from _results import start, write_results

from common.memory import PeakMemory
from pipeline.config import load_config
from render.output.composite import FilmStatistics, clip_stride, composite_film
from render.output.denoise import Guides, denoise_film
from render.output.files import FrameAxis, RenderOutputs
from render.output.tonemap import PERCENTILE_RELATIVE_ERROR, luminance


def synthetic_film(spec: str, folder: Path) -> tuple[np.ndarray, FrameAxis]:
    count, height, width = (int(v) for v in spec.split("x"))
    film = np.lib.format.open_memmap(folder / "frames.npy", "w+", np.float32, (count, height, width, 3))
    rng = np.random.default_rng(0)
    for k in range(count):
        film[k] = np.exp(rng.normal(-4, 2, (height, width, 3))).astype(np.float32)
    film.flush()
    del film
    return np.load(folder / "frames.npy", mmap_mode="r"), FrameAxis(0.0, 0.003, "bins", count)


def flat_guides(height: int, width: int) -> Guides:
    """Guides for a synthetic film: a uniform snow albedo and every normal facing up."""
    normal = np.zeros((height, width, 3), np.float32)
    normal[..., 2] = 1.0
    return Guides(np.full((height, width, 3), 0.8, np.float32), normal)


def main() -> None:
    run = start()
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("source", help="a render stage folder, or TxHxW with --synthetic")
    parser.add_argument("config", type=Path, help="the run's config (its composite section)")
    parser.add_argument("--synthetic", action="store_true")
    parser.add_argument(
        "--denoise",
        action="store_true",
        help="denoise the film first and composite the denoised frames; a render folder's guides come from the "
        "scene folder beside it",
    )
    args = parser.parse_args()
    cfg = load_config(args.config).composite
    passes = []
    with tempfile.TemporaryDirectory() as scratch:
        if args.synthetic:
            frames, film = synthetic_film(args.source, Path(scratch))
            steady = np.asarray(frames[0])
        else:
            outputs = RenderOutputs.read(args.source)
            frames, film, steady = outputs.frames(memory_mapped=True), outputs.axis, outputs.steady()
        out = Path(scratch) / "composite"
        if args.denoise:
            if args.synthetic:
                guides = flat_guides(*frames.shape[1:3])
            else:
                from render.output.guides import guide_buffers

                guides = guide_buffers(Path(args.source).parent / "scene")
            t0 = time.perf_counter()
            with PeakMemory() as memory:
                denoised = denoise_film(
                    frames, guides, out / "frames_denoised.npy", cfg.denoise_quality, False, refine=cfg.denoise_refine
                )
            seconds = time.perf_counter() - t0
            print(
                f"denoise ({cfg.denoise_quality}{', refined' if cfg.denoise_refine else ''}, "
                f"{frames.nbytes / 2**30:.2f} GiB film): {seconds:.1f} s, "
                f"peak {memory.peak_mib:.0f} MiB, {memory.added_mib:.0f} MiB above its start"
            )
            passes.append(_figures("denoise", seconds, memory))
            frames = denoised.frames
        t0 = time.perf_counter()
        with PeakMemory() as memory:
            composite_film(frames, film, cfg, out, streaks=True, steady=steady, exr_attributes={})
        seconds = time.perf_counter() - t0
        print(f"composite: {seconds:.1f} s, peak {memory.peak_mib:.0f} MiB, {memory.added_mib:.0f} MiB above its start")
        passes.append(_figures("composite", seconds, memory))
        histogram = FilmStatistics.measure(frames).clip_exposure(cfg)
        lum = np.concatenate([luminance(frame).ravel() for frame in frames[:: clip_stride(len(frames))]])
        sorted_ = 1.0 / float(np.percentile(lum[lum > 0], cfg.exposure_percentile))
        print(
            f"clip exposure: histogram {histogram:.6g}, sort {sorted_:.6g}, ratio {histogram / sorted_:.6f} "
            f"(stated error {PERCENTILE_RELATIVE_ERROR:.4%})"
        )
        film_gib = frames.nbytes / 2**30
    lines = [
        f"The composite of `{args.source}` ({film_gib:.2f} GiB film) with the composite section of `{args.config}`"
        + (", denoised first." if args.denoise else "."),
        "",
        "| pass | time [s] | peak memory [MiB] | above its start [MiB] |",
        "|---|---|---|---|",
        *(f"| {p['pass']} | {p['seconds']:.1f} | {p['peak_mib']:.0f} | {p['added_mib']:.0f} |" for p in passes),
        "",
        f"Clip exposure from the histogram {histogram:.6g} against the sort of every sampled pixel {sorted_:.6g}: "
        f"ratio {histogram / sorted_:.6f} (the histogram's stated error {PERCENTILE_RELATIVE_ERROR:.4%}).",
    ]
    name = f"bench_composite_{args.config.stem}" + ("_denoise" if args.denoise else "")
    write_results(name, "\n".join(lines), run, rows=passes, standard=not args.synthetic)


def _figures(name: str, seconds: float, memory: PeakMemory) -> dict:
    """One pass's row of the results."""
    return {"pass": name, "seconds": seconds, "peak_mib": memory.peak_mib, "added_mib": memory.added_mib}


if __name__ == "__main__":
    main()
