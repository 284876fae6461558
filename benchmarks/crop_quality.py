"""Issue 28's quality check for the full assets: how clean their delivered frames are, judged on a crop.

A full 1920x1080 film rendered 16 times longer would take a day, so the check renders a window of it: a
``--crop`` WxH window at the centre of the asset's frame, at the asset's own pixel size, iterations and light
paths. For a pinhole camera the centre window is exactly the camera with the same axis and a narrower field of
view, tan(fov'/2) = tan(fov/2) W'/W, so the window is rendered as a camera of its own placed where the full
camera stands (its origin and target, read from the asset's scene stage), with the full film's time axis.

Two renders of the window, with different seeds: the asset's iterations, denoised as the composite stage
does (``composite.denoise_quality``), and ``--factor`` times the iterations as the reference. Both see the
asset's own field: ``geometry.seed`` holds it at the asset's seed while the run's seed changes the render's
noise (the run's seed alone would grow another field for each render). Over the
frames holding more than 1 % of the reference's energy, it prints the per-frame relMSE of the raw and
the denoised frames against the reference, each frame's sum change, and the flicker of the three films.
The reference renders in two independent halves (``--factor`` / 2 times the iterations each) and its own
noise, estimated from their difference, is taken out of every figure (ptpb_bench_scene.FrameError, per frame);
against one render it would stay in as a floor under every delivered frame.

The halves miss part of that noise: light so rare that both miss it leaves them agreeing and the reference
off. A second delivered render (``--second-seed``, the same iterations) measures it: the two delivered renders'
difference gives one render's variance, the reference's is that over ``--factor`` (the path estimator's variance
falls as 1/iterations), and what the halves missed is the difference, a floor left in every figure. The
figures with it taken out too estimate the error against the truth; the raw render's error less its own variance
checks it (an unbiased render's error against the truth is its variance).

    python benchmarks/crop_quality.py configs/assets/video.yaml
    python benchmarks/crop_quality.py configs/assets/video.yaml --iterations 16 --factor 16

Runs go to ``runs/<asset name>_crop*``. The table goes to benchmarks/results/crop_quality_<asset name>.md and
.csv, every figure to a JSON file beside it (git-ignored); with other options than the defaults, to results/local/.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from common.atomic import write_json_atomic
from pipeline.config import load_config
from pipeline.runner import run_dir, run_stages
from pipeline.stages import STAGES
from render.output.denoise import TemporalRoughness, denoise_film, denoise_frame
from render.output.guides import guide_buffers

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _results import LOCAL, RESULTS, is_standard, start, write_results  # noqa: E402
from ptpb_bench_scene import FrameError  # noqa: E402


def _run(config_path: Path, overrides: list[str], stages: tuple[str, ...]) -> tuple[Path, float]:
    """Run the stages; the run folder and the render stage's seconds (0 when it was up to date)."""
    config = load_config(config_path, overrides)
    results = run_stages(config, STAGES, only=stages, quiet=True)
    failed = [r for r in results if r.name in stages and r.status not in ("ran", "skipped")]
    if failed:
        raise SystemExit(f"{config.name}: {failed}")
    return run_dir(config), sum(r.seconds for r in results if r.name == "render")


def crop_overrides(full_scene: Path, width: int, height: int) -> list[str]:
    """The overrides that turn the asset's camera into the centre window of width x height pixels."""
    scene = json.loads((full_scene / "scene.json").read_text())
    camera, film = scene["camera"], scene["film"]
    if camera["fov_axis"] != "x":
        raise SystemExit(f"{full_scene}/scene.json: the crop assumes fov_axis x, not {camera['fov_axis']}")
    fov = math.degrees(2 * math.atan(math.tan(math.radians(camera["fov"] / 2)) * width / camera["width"]))
    return [
        "scene.camera.placement=look_at",
        f"scene.camera.origin={list(camera['origin'])}",
        f"scene.camera.target={list(camera['target'])}",
        f"scene.camera.up={list(camera['up'])}",
        f"scene.camera.fov={fov!r}",
        f"scene.camera.width={width}",
        f"scene.camera.height={height}",
        "reference.downsample=1",  # no references here; the setting must only divide the window
        "scene.film.window=manual",
        f"scene.film.start_opl={film['start_opl']!r}",
        f"scene.film.bin_width_opl={film['bin_width_opl']!r}",
        f"scene.film.temporal_bins={film['temporal_bins']}",
    ]


def flicker(frames: np.ndarray) -> float:
    roughness = TemporalRoughness()
    for frame in frames:
        roughness.add(frame)
    return roughness.value


def main() -> None:
    run = start()
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("config", type=Path, help="an asset config (configs/assets/video.yaml)")
    parser.add_argument("--crop", default="240x135", help="window size WxH at the frame's centre")
    parser.add_argument("--iterations", type=int, help="the delivered render's iterations (default: the config's)")
    parser.add_argument("--factor", type=int, default=16, help="the reference's iterations over the delivered's")
    parser.add_argument("--seed", type=int, default=11, help="the delivered render's seed (the reference: seed + 1)")
    parser.add_argument(
        "--second-seed",
        type=int,
        default=None,
        help="a second delivered render's seed, which measures the reference noise its halves miss (default: "
        "--seed + 10; negative: none)",
    )
    parser.add_argument("--set", action="append", default=[], help="a further override, as the CLI's --set")
    args = parser.parse_args()

    width, height = (int(v) for v in args.crop.split("x"))
    asset = load_config(args.config, args.set)  # --set reaches the denoising settings read below too
    iterations = args.iterations or asset.render.iterations
    name = f"{asset.name}_crop"
    full_scene, _ = _run(args.config, [*args.set, f"name={name}_full"], ("geometry", "scene"))
    # The asset's field in every run; the root seed below changes only the renders' random streams.
    crop = [*crop_overrides(full_scene / "scene", width, height), f"geometry.seed={asset.field_seed()}"]

    def render_crop(label: str, seed: int, crop_iterations: int) -> tuple[Path, float]:
        """The window rendered as run ``<name>_<label>`` with this seed and number of iterations."""
        overrides = [f"name={name}_{label}", f"seed={seed}", f"render.iterations={crop_iterations}"]
        return _run(args.config, [*args.set, *crop, *overrides], ("geometry", "scene", "render"))

    delivered_run, delivered_s = render_crop(f"{iterations}", args.seed, iterations)
    # The reference in two independent halves (seeds + 1 and + 2, factor / 2 times the iterations each): their
    # mean is the 16x render, and their difference measures its own noise, which is taken out below.
    halves, reference_s = [], 0.0
    for k, half in enumerate("ab"):
        run, seconds = render_crop(
            f"{iterations * args.factor}{half}", args.seed + 1 + k, iterations * args.factor // 2
        )
        halves.append(run)
        reference_s += seconds

    second_seed = args.seed + 10 if args.second_seed is None else args.second_seed
    second_run = render_crop(f"{iterations}_s{second_seed}", second_seed, iterations)[0] if second_seed >= 0 else None

    raw = np.load(delivered_run / "render" / "frames.npy")
    error = FrameError(*(np.load(run / "render" / "frames.npy") for run in halves))
    reference = error.reference
    guides = guide_buffers(delivered_run / "scene")

    def delivered(run: Path) -> np.ndarray:
        """The run's frames denoised as the composite stage does."""
        path = run / "crop_denoised.npy"
        denoise_film(
            np.load(run / "render" / "frames.npy"),
            guides,
            path,
            quality=asset.composite.denoise_quality,
            arrival_band=asset.composite.denoise_arrival_band,
            refine=asset.composite.denoise_refine,
        )
        return np.load(path)

    t0 = time.perf_counter()
    denoised = delivered(delivered_run)
    denoise_s = time.perf_counter() - t0

    steady_raw = np.load(delivered_run / "render" / "steady.npy")
    steady_error = FrameError(*(np.load(run / "render" / "steady.npy")[None] for run in halves))
    steady_denoised = denoise_frame(steady_raw, guides, asset.composite.denoise_quality, asset.composite.denoise_refine)
    still = {
        "raw": float(steady_error.per_frame(steady_raw[None])[0]),
        "denoised": float(steady_error.per_frame(steady_denoised[None])[0]),
        "reference_noise": steady_error.reference_noise,
    }

    energy = reference.sum(axis=(1, 2, 3))
    held = np.flatnonzero(energy > 0.01 * energy.sum())
    raw_error, denoised_error = error.per_frame(raw)[held], error.per_frame(denoised)[held]
    reference_noise = error.frame_noise[held]
    sums = denoised.sum(axis=(1, 2)) / np.maximum(raw.sum(axis=(1, 2)), 1e-30)
    result = {
        "config": str(args.config),
        "crop": [width, height],
        "iterations": iterations,
        "reference_iterations": iterations * args.factor,
        "seconds": {"delivered": delivered_s, "reference": reference_s, "denoise": denoise_s},
        "frames_held": held.tolist(),
        "raw_relmse": raw_error.tolist(),
        "denoised_relmse": denoised_error.tolist(),
        "raw_relmse_mean": float(raw_error.mean()),
        "denoised_relmse_mean": float(denoised_error.mean()),
        "denoised_relmse_max": float(denoised_error.max()),
        "reference_noise": reference_noise.tolist(),
        "still_relmse": still,
        "largest_sum_change": float(np.abs(sums[held] - 1).max()),
        "flicker": {"raw": flicker(raw), "denoised": flicker(denoised), "reference": flicker(reference)},
    }
    truth_lines: list[str] = []
    if second_run is not None:
        raw_2 = np.load(second_run / "render" / "frames.npy")
        raw_error_2, denoised_error_2 = error.per_frame(raw_2)[held], error.per_frame(delivered(second_run))[held]
        variance = error.seed_variance(raw, raw_2)[held]
        missed = variance / args.factor - reference_noise
        raw_truth = 0.5 * (raw_error + raw_error_2) - missed
        denoised_truth = [denoised_error - missed, denoised_error_2 - missed]
        result["second"] = {
            "seed": second_seed,
            "raw_relmse_mean": float(raw_error_2.mean()),
            "denoised_relmse_mean": float(denoised_error_2.mean()),
        }
        result["reference_noise_missed"] = missed.tolist()
        result["against_truth"] = {
            "raw_relmse_mean": float(raw_truth.mean()),
            "denoised_relmse_mean": [float(d.mean()) for d in denoised_truth],
            "raw_error_less_variance": float((0.5 * (raw_error + raw_error_2) - variance).mean()),
        }
        ratios = [d.mean() / raw_truth.mean() for d in denoised_truth]
        truth_lines = [
            "",
            f"A second delivered render (seed {second_seed}): raw {raw_error_2.mean():.4f}, denoised "
            f"{denoised_error_2.mean():.4f} ({denoised_error_2.mean() / raw_error_2.mean():.3f} of raw).",
            "",
            f"The reference noise its halves miss, from the two delivered renders' variance "
            f"({variance.mean():.4f} a render) over {args.factor}: {missed.mean():.4f} a frame, left in every figure "
            f"above (the raw renders' error less their variance, {result['against_truth']['raw_error_less_variance']:.4f}, "
            f"measures the same). Taken out too, against the truth: raw {raw_truth.mean():.4f}, denoised "
            f"{denoised_truth[0].mean():.4f} and {denoised_truth[1].mean():.4f} ({ratios[0]:.3f} and {ratios[1]:.3f} of raw).",
        ]
    standard = is_standard(parser, args, ignore=("config",))
    name = f"crop_quality_{asset.name}"
    write_json_atomic((RESULTS if standard else LOCAL) / f"{name}.json", result)
    lines = [
        f"`{args.config}`: a {width}x{height} window at the centre, {iterations} iterations against "
        f"{iterations * args.factor}.",
        "",
        f"Render {delivered_s:.0f} s, reference {reference_s:.0f} s, denoising {denoise_s:.1f} s; "
        f"{held.size} frames hold over 1 % of the energy.",
        "",
        "relMSE against the mean of two independent reference halves, less the reference's own noise (last "
        "column, already subtracted).",
        "",
        "| frame | raw relMSE | denoised relMSE | denoised / raw | reference noise |",
        "|---|---|---|---|---|",
    ]
    for frame, a, b, n in zip(held, raw_error, denoised_error, reference_noise, strict=True):
        lines.append(f"| {frame} | {a:.4f} | {b:.4f} | {b / a:.3f} | {n:.4f} |")
    lines += [
        f"| mean | {raw_error.mean():.4f} | {denoised_error.mean():.4f} | "
        f"{denoised_error.mean() / raw_error.mean():.3f} | {reference_noise.mean():.4f} |",
        "",
        f"The still (the steady image): relMSE raw {still['raw']:.4f}, denoised {still['denoised']:.4f} (reference "
        f"noise {still['reference_noise']:.4f}).",
        "",
        f"Largest change of a frame's sum by denoising: {result['largest_sum_change']:.2e}. Flicker (temporal "
        f"roughness): raw {result['flicker']['raw']:.4f}, denoised {result['flicker']['denoised']:.4f}, "
        f"reference {result['flicker']['reference']:.4f}.",
        *truth_lines,
    ]
    print("\n".join(lines))
    rows = [
        {"frame": int(frame), "raw_relmse": a, "denoised_relmse": b, "reference_noise": n}
        for frame, a, b, n in zip(held, raw_error, denoised_error, reference_noise, strict=True)
    ]
    write_results(name, "\n".join(lines), run, rows=rows, standard=standard)


if __name__ == "__main__":
    main()
