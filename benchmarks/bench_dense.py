"""Equal-time rows against mitransient where paths matter (issue 16, render/core/DESIGN.md §12).

For each row scene (configs/bench/dense_cube.yaml, demo_snow.yaml, thesis_set_1.yaml) this renders a long
mitransient reference once (two halves, cached in benchmarks/results/cache/, as bench_ptpb.py does), then
mitransient's transient_prbvolpath in whole passes for at least ``--seconds`` of wall time, then ours in bins
mode for exactly the time mitransient spent, and reports each one's per-frame relMSE against the reference
(its own noise taken out) and their ratio.
Ours uses the medium estimator that `auto` picks for the scene (reported per row). Writes
benchmarks/results/bench_dense.{md,csv}.

    .venv/bin/python benchmarks/bench_dense.py              # all rows, 60 s each side
    .venv/bin/python benchmarks/bench_dense.py --seconds 10 --rows dense_cube
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))

from ptpb_bench_scene import RESULTS, bench_scene, reference  # noqa: E402

from pipeline.atomic import write_text_atomic  # noqa: E402
from pipeline.config import load_config  # noqa: E402

ROWS = {
    "dense_cube": REPO / "configs" / "bench" / "dense_cube.yaml",
    "demo_snow": REPO / "configs" / "bench" / "demo_snow.yaml",
    "thesis_set_1": REPO / "configs" / "bench" / "thesis_set_1.yaml",
}
THREADS = 2


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
            "rr_depth": cfg.scene.rr_depth,
        }
    )
    result = render(load_scene(scene_dir), settings)
    return result.frames, result.stats


def mitransient_equal_time(scene_dir: Path, seconds: float, cfg) -> tuple[np.ndarray, int, float]:
    """mitransient's transient_prbvolpath in passes of ``cfg.spp_per_pass`` until ``seconds`` of rendering
    (after a warm-up), with the reference section's ``rr_depth`` when set."""
    import mitsuba as mi

    from render.mitsuba.export import scene_to_mitsuba, use_variant
    from render.mitsuba.stage import reference_scene

    use_variant(transient=True)
    scene = reference_scene(scene_dir, cfg)
    spp_per_pass = cfg.spp_per_pass
    scene_dict = scene_to_mitsuba(scene, scene_dir, transient=True, spp=spp_per_pass)
    mi_scene = mi.load_dict(scene_dict)
    mi.render(mi_scene, seed=99_999, spp=2)  # kernel compilation
    total, spp, spent, passes = None, 0, 0.0, 0
    while spent < seconds:
        t0 = time.perf_counter()
        out = mi.render(mi_scene, seed=passes, spp=spp_per_pass)
        frames = np.moveaxis(np.array(out[1], dtype=np.float64)[..., :3], 2, 0)
        spent += time.perf_counter() - t0
        total = frames * spp_per_pass if total is None else total + frames * spp_per_pass
        spp += spp_per_pass
        passes += 1
    assert total is not None
    return total / spp, spp, spent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="wall time of each side per row [s]")
    parser.add_argument("--rows", nargs="*", default=list(ROWS), choices=list(ROWS))
    args = parser.parse_args()
    lines = [
        "| row | ours: estimator | ours relMSE | mitransient relMSE (spp) | ratio ours/mitransient | time each [s] "
        "| ours/reference frame energy |",
        "|---|---|---|---|---|---|---|",
    ]
    csv = ["row,estimator_media_on_paths,ours_relmse,mitransient_relmse,mitransient_spp,ratio,seconds"]
    for row in args.rows:
        cfg = load_config(ROWS[row])
        scene_dir = scene_folder(ROWS[row], cfg)
        ref = reference(scene_dir, cfg.reference)
        error = ref.frame_error()
        # mitransient renders in whole passes and overshoots --seconds by up to one (23 s a pass on the demo
        # row), so it goes first and ours then gets exactly the time it spent.
        frames_mt, spp, spent = mitransient_equal_time(scene_dir, args.seconds, cfg.reference)
        e_mt = error(frames_mt)
        frames, stats = ours(scene_dir, cfg, spent)
        e_ours = error(frames)
        ratio = e_ours / e_mt if e_mt > 0 else float("nan")
        # Per-frame energy against the long reference, over the frames holding more than 1 % of it.
        ref_energy = error.reference.sum(axis=(1, 2, 3))
        energetic = ref_energy > 0.01 * ref_energy.sum()
        energy_ratio = frames.sum(axis=(1, 2, 3))[energetic] / ref_energy[energetic]
        energy_text = f"{energy_ratio.min():.3f}-{energy_ratio.max():.3f} over {energetic.sum()} frames"
        estimator = "paths" if stats["path_media"] else "beams"
        print(
            f"{row}: ours ({estimator}, {stats['iterations']} iterations) relMSE {e_ours:.3g}; mitransient "
            f"({spp} spp, {spent:.0f} s) {e_mt:.3g}; ratio {ratio:.3g}; reference noise {error.reference_noise:.2g}; "
            f"ours/reference frame energy {energy_text}",
            flush=True,
        )
        lines.append(
            f"| {row} | {estimator} | {e_ours:.3g} | {e_mt:.3g} ({spp}) | {ratio:.3g} | {spent:.0f} | {energy_text} |"
        )
        csv.append(f"{row},{stats['path_media']},{e_ours:.6g},{e_mt:.6g},{spp},{ratio:.6g},{spent:.3f}")
    RESULTS.mkdir(parents=True, exist_ok=True)
    write_text_atomic(RESULTS / "bench_dense.md", "\n".join(lines) + "\n")
    write_text_atomic(RESULTS / "bench_dense.csv", "\n".join(csv) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
