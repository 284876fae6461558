"""Equal-time rows against mitransient where paths matter (issues 16 and 28, render/core/DESIGN.md §12).

For each row scene (configs/bench/dense_cube.yaml, demo_snow.yaml, thesis_set_1.yaml) this renders a long
mitransient reference once (two halves in ``reference.tiles`` tiles, as the reference stage renders, cached in
benchmarks/results/cache/, as bench_ptpb.py does), then mitransient's transient_prbvolpath three times, in
whole passes for up to ``--seconds`` of wall time each: as shipped (Russian roulette from depth 5, the whole
film in metres), tuned (roulette from the row's ``reference.rr_depth``, at least 1000, or ``--tuned-rr``; its
survival cap of 0.95 per collision otherwise ends the long paths of dense snow), and tuned and tiled as the
reference (Mitsuba's single-precision ray offsets skip some of a dense medium where the scene lies far from
the origin; tiles cost loads, the whole film does not: render/mitsuba/export.py). Ours then renders in bins
mode for the longest of the three times. Each mitransient error is brought to ours' time as relMSE x time
(unbiased Monte Carlo: relMSE falls as 1/t), and the ratio is taken against the best of the three. Errors are
per-frame relMSE against the reference (its own noise, as its two halves' difference shows it, taken out), over
all frames and over the late third, where snow's error lives. The halves miss light so rare that both miss it:
that part of the reference's noise is measured from the tiled baseline, which renders as the reference does
(``missed_reference_noise``), and a second ratio takes it out of every error as well. Same phase model and time
bins on both sides: both render the scene folder's scene.
Ours uses the medium estimator that `auto` picks for the scene (reported per row). Writes
benchmarks/results/bench_dense.md and .csv (results/local/ with other arguments than the defaults).

    .venv/bin/python benchmarks/bench_dense.py              # all rows, 60 s each side
    .venv/bin/python benchmarks/bench_dense.py --seconds 10 --rows dense_cube
"""

from __future__ import annotations

import argparse
import math
import subprocess
import sys
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))

from _results import is_standard, start, write_results  # noqa: E402
from ptpb_bench_scene import bench_scene, reference  # noqa: E402

from pipeline.config import load_config  # noqa: E402

ROWS = {
    "dense_cube": REPO / "configs" / "bench" / "dense_cube.yaml",
    "demo_snow": REPO / "configs" / "bench" / "demo_snow.yaml",
    "thesis_set_1": REPO / "configs" / "bench" / "thesis_set_1.yaml",
}
# Rows whose reference renders each channel on its own (ptpb_bench_scene.reference): the thesis row's medium is
# chromatic (sigma_t 53 / 36 / 24 per m), and mitransient's chromatic weights give its reference a tail that
# 16384 spp does not converge (benchmarks/README.md).
PER_CHANNEL = {"thesis_set_1"}
THREADS = 2
BASELINES = ("shipped", "tuned", "tuned_tiled")


def scene_folder(path: Path, cfg) -> Path:
    """The row's scene folder: bench_scene's cache, or for a field grown by the geometry stage the
    pipeline's own geometry and scene stages (cached by their manifests) under runs/<name>/."""
    if any(obj.shape == "penitentes" for obj in cfg.scene.objects):
        command = [sys.executable, "-m", "pipeline", "run", str(path), "--stage", "geometry", "--stage", "scene"]
        subprocess.run(command, check=True, cwd=REPO)
        return REPO / "runs" / cfg.name / "scene"
    return bench_scene(cfg)


def ours(scene_dir: Path, cfg, seconds: float) -> tuple[np.ndarray, dict]:
    from render.ptpb import load_scene, render

    settings = cfg.render.model_validate(
        {
            **cfg.render.model_dump(),
            "time_budget_s": seconds,
            "threads": THREADS,
            "seed": 0,
            "snapshot_every": 0,
            "frame_mode": "bins",
            "max_depth": cfg.scene.max_depth,
            "rr_depth": cfg.render.rr_depth,
        }
    )
    result = render(load_scene(scene_dir), settings)
    return result.frames, result.stats


def mitransient_equal_time(
    scene_dir: Path, seconds: float, cfg, rr_depth: int, tiles: int
) -> tuple[np.ndarray, int, float]:
    """mitransient's transient_prbvolpath in passes of ``cfg.spp_per_pass`` for up to ``seconds`` of rendering
    (after a warm-up that compiles its kernels), with Russian roulette from ``rr_depth``, in ``tiles`` tiles
    (0: the whole film in metres; render/mitsuba/export.py)."""
    from render.mitsuba.passes import render_transient
    from render.mitsuba.stage import reference_scene

    scene = reference_scene(scene_dir, cfg.model_copy(update={"rr_depth": rr_depth}))
    render_transient(scene, scene_dir, spp=2, spp_per_pass=2, seed=99_999, quiet=True, tiles=tiles)
    frames, _, timing = render_transient(
        scene,
        scene_dir,
        spp=cfg.spp_per_pass,
        spp_per_pass=cfg.spp_per_pass,
        time_budget_s=seconds,
        quiet=True,
        tiles=tiles,
    )
    return frames, int(timing["spp"]), float(timing["seconds"])


@dataclass(frozen=True)
class Baseline:
    """One mitransient run of a row: its errors (all frames, late third) and its cost."""

    relmse: float
    late_relmse: float
    spp: int
    seconds: float

    def at(self, seconds: float, floor: tuple[float, float] = (0.0, 0.0)) -> tuple[float, float]:
        """Both errors less ``floor``, brought to ``seconds`` by relMSE x time (unbiased Monte Carlo)."""
        scale = self.seconds / seconds
        return (self.relmse - floor[0]) * scale, (self.late_relmse - floor[1]) * scale


def missed_reference_noise(error: float, spp: int, reference_spp: int, halves_noise: float) -> float:
    """The reference's own noise that its halves miss (light so rare that both miss it; they agree there), a
    floor left in every error, from the tiled baseline: it is the reference's estimator at ``spp``, so its error
    against the reference is V/spp + V/N less the halves' estimate, V = (error + halves) / (1/spp + 1/N), and the
    reference's noise V/N less the halves' estimate is what they missed. Heavy tails make ``error``, and this, if
    anything low."""
    variance = (error + halves_noise) / (1.0 / spp + 1.0 / reference_spp)
    return variance / reference_spp - halves_noise


def ratio_of(ours_error: float, baseline_error: float) -> float:
    """ours / baseline, NaN when either corrected error is inside the reference's own noise (at or below 0)."""
    return ours_error / baseline_error if ours_error > 0 and baseline_error > 0 else float("nan")


def ratios_against_best(
    ours: tuple[float, float], baselines: Iterable[Baseline], seconds: float, floor: tuple[float, float] = (0.0, 0.0)
) -> tuple[float, float]:
    """Ours' errors (all frames, late third) over the best baseline's at ours' ``seconds``, ``floor`` out of each."""
    at_ours = [b.at(seconds, floor) for b in baselines]
    return (
        ratio_of(ours[0] - floor[0], min(e for e, _ in at_ours)),
        ratio_of(ours[1] - floor[1], min(e_late for _, e_late in at_ours)),
    )


def main() -> None:
    run = start()
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="wall time of each side per row [s]")
    parser.add_argument("--rows", nargs="*", default=list(ROWS), choices=list(ROWS))
    parser.add_argument(
        "--tuned-rr",
        type=int,
        default=None,
        help="roulette depth of the tuned mitransient [-]; default: the row's reference.rr_depth, at least 1000",
    )
    args = parser.parse_args()
    lines = [
        "| row | ours: estimator | ours relMSE (late third) | mitransient shipped, rr 5 (late; spp) "
        "| tuned (late; rr; spp) | tuned, tiled (late; tiles; spp) | ratio ours / best (late third) "
        "| the same, the reference's missed noise out (late third; that noise) | ours [s] "
        "| ours/reference frame energy |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    rows = []
    for row in args.rows:
        cfg = load_config(ROWS[row])
        set_rr = cfg.reference.rr_depth if isinstance(cfg.reference.rr_depth, int) else 0
        tuned_rr = args.tuned_rr or max(1000, set_rr)
        # (roulette depth, tiles) of each baseline; the tiled one renders as the reference does.
        baselines = {"shipped": (5, 0), "tuned": (tuned_rr, 0), "tuned_tiled": (tuned_rr, cfg.reference.tiles)}
        scene_dir = scene_folder(ROWS[row], cfg)
        per_channel = row in PER_CHANNEL
        ref = reference(scene_dir, cfg.reference, per_channel=per_channel)
        error = ref.frame_error()
        first_late = 2 * error.reference.shape[0] // 3
        late = error.late(first_late)
        # mitransient renders in whole passes and stops before the pass that would overrun --seconds, so it
        # goes first and ours then gets the longest of its times.
        measured = {}
        for name, (rr, tiles) in baselines.items():
            frames_mt, spp, spent = mitransient_equal_time(scene_dir, args.seconds, cfg.reference, rr, tiles)
            measured[name] = Baseline(error(frames_mt), late(frames_mt[first_late:]), spp, spent)
            print(f"{row}: mitransient {name} (rr {rr}, tiles {tiles}): {spp} spp in {spent:.0f} s", flush=True)
        seconds = max(b.seconds for b in measured.values())
        frames, stats = ours(scene_dir, cfg, seconds)
        e_ours, e_ours_late = error(frames), late(frames[first_late:])
        # relMSE x time is what a Monte Carlo render holds fixed: each baseline at ours' time (the table's cells).
        runs = {name: Baseline(*b.at(seconds), b.spp, b.seconds) for name, b in measured.items()}
        ratio, late_ratio = ratios_against_best((e_ours, e_ours_late), measured.values(), seconds)
        # The same with the reference's missed noise taken out of every error, where the tiled baseline renders
        # exactly as the reference (same roulette and tiles, all channels at once); NaN otherwise.
        floors = (math.nan, math.nan)
        if tuned_rr == (set_rr or cfg.render.rr_depth) and not per_channel:
            tiled = measured["tuned_tiled"]
            floors = (
                missed_reference_noise(tiled.relmse, tiled.spp, ref.spp, error.reference_noise),
                missed_reference_noise(tiled.late_relmse, tiled.spp, ref.spp, late.reference_noise),
            )
        floored = ratios_against_best((e_ours, e_ours_late), measured.values(), seconds, floors)
        # Per-frame energy against the long reference, over the frames holding more than 1 % of it.
        ref_energy = error.reference.sum(axis=(1, 2, 3))
        energetic = ref_energy > 0.01 * ref_energy.sum()
        energy_ratio = frames.sum(axis=(1, 2, 3))[energetic] / ref_energy[energetic]
        energy_text = f"{energy_ratio.min():.3f}-{energy_ratio.max():.3f} over {energetic.sum()} frames"
        estimator = "paths" if stats["path_media"] else "beams"
        print(
            f"{row}: ours ({estimator}, {stats['iterations']} iterations, {seconds:.0f} s) relMSE {e_ours:.3g} "
            f"(late third {e_ours_late:.3g}); mitransient at ours' time "
            + "; ".join(f"{n} {b.relmse:.3g} (late {b.late_relmse:.3g})" for n, b in runs.items())
            + f"; ratio against the best {ratio:.3g} (late third {late_ratio:.3g}); reference noise "
            f"{error.reference_noise:.2g}, of which its halves missed {floors[0]:.2g} (late third {floors[1]:.2g}); "
            f"with that taken out too, ratio {floored[0]:.3g} (late third {floored[1]:.3g}); ours/reference frame "
            f"energy {energy_text}",
            flush=True,
        )
        shipped, tuned, tiled = (runs[b] for b in BASELINES)
        cells = [
            f"{shipped.relmse:.3g} ({shipped.late_relmse:.3g}; {shipped.spp})",
            f"{tuned.relmse:.3g} ({tuned.late_relmse:.3g}; rr {tuned_rr}; {tuned.spp})",
            f"{tiled.relmse:.3g} ({tiled.late_relmse:.3g}; {cfg.reference.tiles}; {tiled.spp})",
        ]
        ratio_text, late_text, floored_text, floored_late_text = (
            "n/a" if math.isnan(r) else f"{r:.3g}" for r in (ratio, late_ratio, *floored)
        )
        lines.append(
            f"| {row} | {estimator} | {e_ours:.3g} ({e_ours_late:.3g}) | {' | '.join(cells)} "
            f"| **{ratio_text}** ({late_text}) | {floored_text} ({floored_late_text}; {floors[0]:.2g}) "
            f"| {seconds:.0f} | {energy_text} |"
        )
        rows.append(
            {
                "row": row,
                "estimator_media_on_paths": stats["path_media"],
                "seconds": seconds,
                "ours_relmse": e_ours,
                "ours_late_relmse": e_ours_late,
                **{
                    f"{name}_{key}": getattr(runs[name], key)
                    for name in BASELINES
                    for key in ("relmse", "late_relmse", "spp", "seconds")
                },
                "tuned_rr": tuned_rr,
                "tiles": cfg.reference.tiles,
                "ratio": ratio,
                "late_ratio": late_ratio,
                "missed_noise": floors[0],
                "late_missed_noise": floors[1],
                "ratio_missed_out": floored[0],
                "late_ratio_missed_out": floored[1],
            }
        )
    lines.append("")
    lines.append(
        "mitransient's errors are brought to ours' time as relMSE x time; in brackets: the late third of the "
        "frames, and the spp each baseline rendered. The reference's missed noise (light both its halves miss) "
        "is measured from the tiled baseline, the reference's own estimator (n/a where their roulette differs or "
        "the reference renders each channel on its own). A ratio is n/a where a corrected error is at or below "
        "zero, inside the reference's own noise."
    )
    print("\n".join(lines))
    write_results("bench_dense", "\n".join(lines), run, rows=rows, standard=is_standard(parser, args))


if __name__ == "__main__":
    main()
