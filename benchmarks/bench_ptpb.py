"""PTPB performance on configs/bench/ptpb.yaml: equal error against mitransient (transient) and Mitsuba
volpath (steady), one gate-mode pass against T single-gate passes, throughput, thread scaling and peak
memory. Every row comes from one run on one machine; the results' header names the machine and its load.

Run with `make bench` (or `.venv/bin/python benchmarks/bench_ptpb.py`; `--quick` for a smoke run with
small budgets). Prints the table and writes benchmarks/results/ptpb.md, ptpb.csv and
ptpb_error_vs_time.png (with --quick, to results/local/). The first run also builds the scene and renders
the long reference (mitransient at reference.transient_spp, minutes), both cached under benchmarks/results/cache/.

Equal error: our error-against-time curve (per-frame relMSE against the reference with the
reference's own noise taken out, benchmarks/ptpb_bench_scene.py; mean of two seeds) is set against the
path tracer's expected error V / n after n spp (PathTracerCurve) and its measured time per spp. The
headline takes our error at the end of our run and divides the time the path tracer needs for the same
expected error by ours; a second row takes the path tracer's expected error after the spp it renders
here and finds when ours reaches it. Ours is rendered in bins mode (transient) and steady mode
(steady); its time includes everything inside render(); the path tracers' time is that of their
mi.render passes after one warm-up render that compiles their kernels.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from _results import LOCAL, RESULTS, load_average, machine, start, write_results  # noqa: E402
from ptpb_bench_scene import REPO, FrameError, bench_scene, reference  # noqa: E402

from pipeline.config import load_config  # noqa: E402

CONFIG = REPO / "configs" / "bench" / "ptpb.yaml"
BEAM_BYTES = 112  # sizeof(ptpb::Beam), render/core/include/ptpb/beams.hpp
THREADS = 2


# ---------------------------------------------------------------- small helpers


def digest(*arrays: np.ndarray) -> str:
    h = hashlib.sha256()
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:16]


def time_to_reach(curve: list[tuple[float, float]], target: float) -> tuple[float | None, str]:
    """Seconds at which a (seconds, error) curve first falls to ``target`` and how that was found: log-log
    interpolation between the bracketing points, the first point's time when it starts below (an upper
    bound), or None when it never gets there."""
    if not curve:
        return None, "no points"
    if curve[0][1] <= target:
        return curve[0][0], "at or before the first point"
    for (t0, e0), (t1, e1) in zip(curve, curve[1:]):
        if e0 > target >= e1:
            if e1 <= 0 or e0 <= 0:
                return t1, "bracketed"
            w = math.log(e0 / target) / math.log(e0 / e1)
            return math.exp(math.log(t0) + w * math.log(t1 / t0)), "interpolated"
    return None, "not reached"


class PathTracerCurve:
    """A path tracer's independent passes of equal spp. Unbiased, its expected error after n spp is
    V / n, with V the error of one sample. Fireflies make any estimate of V from a few passes noisy, so
    it takes the smallest (the most favourable to the path tracer) of: the spread of the passes
    (spp * mean over values of weight * variance across passes), the median error of one pass times its
    spp (the typical rather than the expected error), and, where the reference was rendered by the
    same estimator, the spread of the reference's halves (its spp times its noise term). The realised
    curve of the running mean (``points``: spp, seconds, error) is kept for the figure."""

    def __init__(self, points: list[tuple[int, float, float]], spread: float, median: float, seconds_per_spp: float):
        self.points = points
        self.seconds_per_spp = seconds_per_spp
        self.estimates = {f"spread of its {len(points)} passes": spread, "median pass": median}

    def add_reference_estimate(self, ref_spp: int, reference_noise: float) -> None:
        self.estimates[f"reference halves ({ref_spp} spp)"] = ref_spp * reference_noise

    @property
    def one_spp_error(self) -> float:
        return min(self.estimates.values())

    @property
    def source(self) -> str:
        chosen = min(self.estimates, key=self.estimates.get)
        others = ", ".join(f"{k} {v:.3g}" for k, v in self.estimates.items() if k != chosen)
        return f"{chosen} (smallest; {others})"

    def expected_error(self, spp: float) -> float:
        return self.one_spp_error / spp

    def seconds_for(self, error: float) -> tuple[float, float]:
        """(seconds, spp) to reach the expected ``error``."""
        spp = self.one_spp_error / error
        return spp * self.seconds_per_spp, spp

    def curve(self) -> list[tuple[float, float]]:
        return [(t, e) for _, t, e in self.points]

    def expected_curve(self, up_to_spp: float) -> list[tuple[float, float]]:
        spp = np.geomspace(self.points[0][0], max(up_to_spp, 2 * self.points[0][0]), 24)
        return [(n * self.seconds_per_spp, self.expected_error(n)) for n in spp]


# ---------------------------------------------------------------- renders


def ours_transient(core: dict, cfg, error: FrameError, iterations: int, every: int):
    """Bins-mode render; per-frame relMSE every ``every`` iterations (checkpoint callback, its own
    time taken out of the curve)."""
    from render.ptpb.api import render

    points, spent = [], [0.0]

    def on_checkpoint(state: dict) -> bool:
        t0 = time.perf_counter()
        n = state["stats"]["iterations"]
        points.append((state["stats"]["time_total_s"] - spent[0], error(np.asarray(state["frames"]) / n), n))
        spent[0] += time.perf_counter() - t0
        return True

    settings = cfg.model_validate(
        {
            **cfg.model_dump(),
            "iterations": iterations,
            "threads": THREADS,
            "checkpoint_every_iterations": every,
            "snapshot_every": 0,
            "frame_mode": "bins",
        }
    )
    result = render(core, settings, checkpoint=on_checkpoint)
    points.append((result.stats["time_total_s"] - spent[0], error(result.frames), iterations))
    return result, points


def ours_steady(core: dict, cfg, error: FrameError, iterations: int, every: int):
    from render.ptpb.api import render

    scene = {**core, "film": {**core["film"], "frame_mode": "steady"}}
    settings = cfg.model_validate(
        {
            **cfg.model_dump(),
            "iterations": iterations,
            "threads": THREADS,
            "snapshot_every": every,
            "frame_mode": "steady",
        }
    )
    result = render(scene, settings)
    points = [(t, error(s), n) for (n, s), t in zip(result.snapshots, result.snapshot_seconds)]
    return result, points


def path_tracer(scene_dir: Path, error: FrameError, integrator: str, passes: int, spp: int) -> PathTracerCurve:
    """mitransient's transient_prbvolpath (frames), or volpath / prbvolpath (steady image): ``passes``
    independent passes of ``spp`` each; seconds count the mi.render calls only, after a warm-up render
    that compiles the kernels."""
    import mitsuba as mi

    from render.mitsuba.export import scene_to_mitsuba, use_variant
    from render.scene.model import Scene

    transient = integrator == "transient_prbvolpath"
    use_variant(transient=transient)
    scene_dict = scene_to_mitsuba(Scene.load(scene_dir / "scene.json"), scene_dir, transient=transient, spp=spp)
    scene_dict["integrator"]["type"] = integrator
    mi_scene = mi.load_dict(scene_dict)

    def one(seed: int, n: int) -> np.ndarray:
        out = mi.render(mi_scene, seed=seed, spp=n)
        if transient:  # (H, W, T, C) -> (T, H, W, C)
            return np.moveaxis(np.array(out[1], dtype=np.float64)[..., :3], 2, 0)
        return np.array(out, dtype=np.float64)[None, ..., :3]

    one(10_000, 4)  # warm-up: kernel compilation
    total = squares = None
    seconds, points, pass_errors = 0.0, [], []
    for i in range(passes):
        t0 = time.perf_counter()
        image = one(i, spp)
        seconds += time.perf_counter() - t0
        total = image.copy() if total is None else total + image
        squares = image**2 if squares is None else squares + image**2
        points.append((spp * (i + 1), seconds, error(total / (i + 1))))
        pass_errors.append(error(image))
    spread = (squares - total**2 / passes) / (passes - 1)  # per-value variance of one pass
    return PathTracerCurve(
        points,
        spp * float(np.mean(spread * error.weight)),
        spp * float(np.median(pass_errors)),
        seconds / (passes * spp),
    )


def one_pass_against_many(core: dict, cfg, iterations: int, paths: int):
    """T gate frames in one pass against T renders of one gate each (temporal_bins = 1 centred on
    frame k, the same R_0, T_0, M and iterations); returns times and the largest frame difference."""
    from render.ptpb.api import render

    film = core["film"]
    frames = film["temporal_bins"]
    settings = cfg.model_validate(
        {
            **cfg.model_dump(),
            "iterations": iterations,
            "threads": THREADS,
            "light_paths_per_iteration": paths,
            "frame_mode": "gate",
            "alpha": None,
            "snapshot_every": 0,
        }
    )
    # The one pass lasts about 0.1 s, so a single timing of it is noisy, while the 64 passes add up
    # their noise: its time is the median of five renders.
    times = []
    for _ in range(5):
        t0 = time.perf_counter()
        whole = render(core, settings)
        times.append(time.perf_counter() - t0)
    t_one = float(np.median(times))
    t_many, worst = 0.0, 0.0
    scale = float(np.abs(whole.frames).max()) or 1.0
    for k in range(frames):
        gate = {**film, "temporal_bins": 1, "start_opl": film["start_opl"] + k * film["bin_width_opl"]}
        t0 = time.perf_counter()
        single = render({**core, "film": gate}, settings)
        t_many += time.perf_counter() - t0
        worst = max(worst, float(np.abs(single.frames[0] - whole.frames[k]).max()) / scale)
    return t_one, t_many, worst, whole.stats


def scaling(core: dict, cfg, iterations: int, repeats: int):
    """Best wall time of ``repeats`` renders at 1 and THREADS threads (alternating), the process CPU
    time of that render, and the images' digests."""
    from render.ptpb.api import render

    best, cpu, hashes = {}, {}, {}
    for _ in range(repeats):
        for threads in (1, THREADS):
            settings = cfg.model_validate(
                {
                    **cfg.model_dump(),
                    "iterations": iterations,
                    "threads": threads,
                    "snapshot_every": 0,
                    "frame_mode": "bins",
                }
            )
            c0, t0 = time.process_time(), time.perf_counter()
            r = render(core, settings)
            seconds, cpu_seconds = time.perf_counter() - t0, time.process_time() - c0
            if seconds < best.get(threads, math.inf):
                best[threads], cpu[threads] = seconds, cpu_seconds
            hashes[threads] = digest(r.frames, r.steady)
    return best, cpu, hashes


def peak_rss(reset: bool = False) -> int:
    """This process's peak resident memory (VmHWM), bytes; ``reset`` restarts it at the current RSS.
    Not getrusage's ru_maxrss: Linux carries that across exec, so a child started by a large parent
    would report the parent's peak."""
    if reset:
        Path("/proc/self/clear_refs").write_text("5")
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) * 1024
    raise RuntimeError("no VmHWM in /proc/self/status")


def memory_worker(spec: dict) -> None:
    """Runs in its own process: one render, then prints its peak RSS against frames + beams."""
    import psutil

    from render.engine import load_core_scene
    from render.ptpb.api import render

    cfg = load_config(CONFIG)
    core = load_core_scene(bench_scene(cfg))
    film = core["film"]
    frames = spec["frames"]
    core["film"] = {
        **film,
        "temporal_bins": frames,
        "bin_width_opl": film["bin_width_opl"] * film["temporal_bins"] / frames,
    }
    settings = cfg.render.model_validate(
        {
            **cfg.render_settings().model_dump(),
            "iterations": spec["iterations"],
            "light_paths_per_iteration": spec["paths"],
            "threads": THREADS,
            "snapshot_every": 0,
            "frame_mode": "bins",
        }
    )
    before = psutil.Process().memory_info().rss
    peak_rss(reset=True)
    r = render(core, settings)
    peak = peak_rss()
    h, w = r.steady.shape[:2]
    beams = r.stats["beams"] / r.stats["iterations"]
    print(
        json.dumps(
            {
                "frames": frames,
                "paths": spec["paths"],
                "rss_before": before,
                "peak": peak,
                "frame_buffer": (frames + 3) * h * w * 3 * 4,
                "beams_per_iteration": beams,
                "beam_storage": beams * BEAM_BYTES,
                "accel_references": r.stats["accel_references"] / r.stats["iterations"],
                "film_doubles": (frames + 3) * h * w * 3 * 8,
            }
        )
    )


def memory(specs: list[dict]) -> list[dict]:
    out = []
    for spec in specs:
        text = subprocess.run(
            [sys.executable, __file__, "--memory-worker", json.dumps(spec)], check=True, capture_output=True, text=True
        ).stdout
        out.append(json.loads(text.strip().splitlines()[-1]))
    return out


# ---------------------------------------------------------------- table and figure


class Table:
    def __init__(self):
        self.rows: list[dict] = []

    def add(
        self,
        section: str,
        measure: str,
        value,
        unit: str = "",
        target: str = "",
        met: bool | None = None,
        note: str = "",
    ):
        text = value if isinstance(value, str) else (f"{value:.4g}" if isinstance(value, float) else str(value))
        self.rows.append(
            {
                "section": section,
                "measure": measure,
                "value": text,
                "unit": unit,
                "target": target,
                "met": "" if met is None else ("yes" if met else "NO"),
                "note": note,
            }
        )

    def markdown(self) -> str:
        keys = ["section", "measure", "value", "unit", "target", "met", "note"]
        lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
        lines += ["| " + " | ".join(str(r[k]).replace("|", "/") for k in keys) + " |" for r in self.rows]
        return "\n".join(lines)


def plot(path: Path, transient: dict, steady: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, (title, curves) in zip(
        axes, [("transient, per-frame relMSE (64 bins)", transient), ("steady relMSE", steady)]
    ):
        for label, (pts, style) in curves.items():
            pts = [(t, e) for t, e in pts if e > 0]
            if pts:
                ax.loglog(*zip(*pts), style, label=label)
        ax.set_xlabel("wall time [s]")
        ax.set_ylabel("relMSE, reference noise removed")
        ax.set_title(title)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


# ---------------------------------------------------------------- main


def average_curves(runs: list[list[tuple[float, float, int]]]) -> list[tuple[float, float, int]]:
    """The mean (seconds, error) of runs checkpointed at the same iterations."""
    return [
        (float(np.mean([r[i][0] for r in runs])), float(np.mean([r[i][1] for r in runs])), runs[0][i][2])
        for i in range(min(len(r) for r in runs))
    ]


def equal_error_rows(
    table: Table,
    section: str,
    ours: list[tuple[float, float, int]],
    other: PathTracerCurve,
    other_name: str,
    target: float,
    level_spp: int,
    seeds: int,
) -> None:
    """Rows for the speed-up at our final error (held against ``target``) and at the path tracer's
    expected error after ``level_spp``."""
    table.add(
        section,
        f"{other_name}: expected relMSE after n spp",
        f"{other.one_spp_error:.4g} / n",
        "",
        note=f"{other.seconds_per_spp * 1e3:.2f} ms per spp (timed passes); V from {other.source}",
    )
    t_end, e_end, n_end = ours[-1]
    t_other, spp_other = other.seconds_for(e_end)
    headline = t_other / t_end
    table.add(
        section, f"ours: relMSE after {n_end} iterations", e_end, "", note=f"{t_end:.2f} s; mean of {seeds} seeds"
    )
    table.add(section, f"{other_name}: time to the same relMSE", t_other, "s", note=f"{spp_other:.0f} spp")
    table.add(
        section, "speed-up at equal error (our final error)", headline, "x", f">= {target:g}x", headline >= target
    )
    level = other.expected_error(level_spp)
    t_ours, how = time_to_reach([(t, e) for t, e, _ in ours], level)
    t_other = level_spp * other.seconds_per_spp
    if t_ours:
        bound = ">= " if how.startswith("at or before") else ""
        table.add(
            section,
            f"speed-up at {other_name}'s error after {level_spp} spp (relMSE {level:.3g})",
            f"{bound}{t_other / t_ours:.3g}",
            "x",
            note=f"ours {t_ours:.2f} s ({how}), {other_name} {t_other:.2f} s",
        )
    else:
        table.add(
            section,
            f"speed-up at {other_name}'s error after {level_spp} spp (relMSE {level:.3g})",
            "not reached",
            "",
            note=f"ours ends at {e_end:.3g}",
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small budgets: checks the script, not the figures")
    parser.add_argument("--memory-worker", help=argparse.SUPPRESS)
    args = parser.parse_args()
    os.chdir(REPO)  # results and caches are written under the repository
    if args.memory_worker:
        memory_worker(json.loads(args.memory_worker))
        return

    from render.engine import load_core_scene

    quick = args.quick
    run = start()
    config = load_config(CONFIG)
    scene_dir = bench_scene(config)
    ref = reference(scene_dir, config.reference)
    core = load_core_scene(scene_dir)
    cfg = config.render_settings()  # the render section with the scene's path depth, as the pipeline renders
    frames_error, steady_error = ref.frame_error(), ref.steady_error()
    film = core["film"]
    cam = core["camera"]
    table = Table()
    table.add(
        "setup",
        "machine",
        machine(),
        "",
        note=f"load average (1/5/15 min) at start {load_average(run.load)}",
    )
    table.add(
        "setup",
        "scene",
        f"{cam['width']}x{cam['height']} px, {film['temporal_bins']} bins of {film['bin_width_opl'] * 100:.2f} cm",
        "",
        note=f"{CONFIG.relative_to(REPO)}: 2 m penitente patch "
        "(benchmarks/data/penitente_patch.ply), index-matched snow, 1 m area light",
    )
    table.add(
        "setup",
        "reference",
        f"mitransient {ref.spp} spp",
        "",
        note=f"noise term removed from every error: frames {frames_error.reference_noise:.3g}, "
        f"steady {steady_error.reference_noise:.3g}; rendered in {ref.seconds:.0f} s (cached)",
    )

    iterations = 8 if quick else cfg.iterations
    passes, pass_spp = (4, 16) if quick else (16, 64)
    seeds = [config.seed + k for k in range(1 if quick else 2)]
    every = 2 if quick else 4  # checkpoint copies cost ours ~15 ms each: few of them

    # 1. Equal error, transient: ours (bins) against mitransient.
    print("equal error, transient ...", flush=True)
    runs = [
        ours_transient(core, cfg.model_copy(update={"seed": seed}), frames_error, iterations, every) for seed in seeds
    ]
    result, ours_t = runs[0][0], average_curves([r[1] for r in runs])
    mitr = path_tracer(scene_dir, frames_error, "transient_prbvolpath", passes, pass_spp)
    mitr.add_reference_estimate(ref.spp, frames_error.reference_noise)
    equal_error_rows(table, "equal error, transient", ours_t, mitr, "mitransient", 10.0, passes * pass_spp, len(seeds))
    # 2. Equal error, steady: ours (steady mode) against volpath.
    print("equal error, steady ...", flush=True)
    runs = [ours_steady(core, cfg.model_copy(update={"seed": seed}), steady_error, iterations, every) for seed in seeds]
    steady_result, ours_s = runs[0][0], average_curves([r[1] for r in runs])
    volpath = path_tracer(scene_dir, steady_error, "volpath", passes, pass_spp)
    equal_error_rows(table, "equal error, steady", ours_s, volpath, "volpath", 2.0, passes * pass_spp, len(seeds))
    prb = path_tracer(scene_dir, steady_error, "prbvolpath", passes, pass_spp)
    prb.add_reference_estimate(ref.spp, steady_error.reference_noise)  # its steady image is the reference's
    equal_error_rows(
        table, "equal error, steady (prbvolpath)", ours_s, prb, "prbvolpath", 2.0, passes * pass_spp, len(seeds)
    )
    mean_ratio = steady_result.steady.mean((0, 1)) / steady_error.reference.mean((0, 1, 2))
    table.add(
        "equal error, steady",
        "our steady mean / reference, per channel",
        ", ".join(f"{v:.3f}" for v in mean_ratio),
        "",
        note="the kernel's bias near the boundary",
    )

    # 3. Throughput and time split of the transient run.
    s = result.stats
    split = {
        "light tracing": s["time_light_s"],
        "beam structure build": s["time_build_s"],
        "camera pass (queries + gather)": s["time_camera_s"],
    }
    other = s["time_total_s"] - sum(split.values())
    for name, seconds in split.items():
        table.add("throughput", f"time in {name}", f"{seconds:.2f} s ({100 * seconds / s['time_total_s']:.0f} %)")
    table.add(
        "throughput",
        "time elsewhere (buffers, sums, checkpoints)",
        f"{other:.2f} s ({100 * other / s['time_total_s']:.0f} %)",
    )
    table.add("throughput", "light paths / s", s["light_paths"] / s["time_light_s"], "1/s", note="of tracing time")
    table.add(
        "throughput",
        "beams / s",
        s["beams"] / s["time_light_s"],
        "1/s",
        note=f"{s['beams'] / s['iterations']:.0f} beams per iteration of {s['light_paths'] // s['iterations']} paths",
    )
    table.add("throughput", "query rays / s", s["queries"] / s["time_camera_s"], "1/s", note="of camera-pass time")
    table.add(
        "throughput",
        "ray-beam pair evaluations / s",
        s["pair_evaluations"] / s["time_camera_s"],
        "1/s",
        note=f"{s['pair_evaluations'] / s['queries']:.1f} pairs and {s['candidates'] / s['queries']:.1f} "
        f"candidates per query; {s['false_positives']} false positives",
    )
    table.add(
        "throughput",
        "whole render",
        f"{s['iterations'] / s['time_total_s']:.2f} iterations/s",
        "",
        note=f"{s['iterations']} iterations, {THREADS} threads",
    )

    # 4. One pass against T passes (gate mode).
    print("one pass against T passes ...", flush=True)
    gate_iterations, gate_paths = (2, 2000) if quick else (4, 5000)
    t_one, t_many, worst, gate_stats = one_pass_against_many(core, cfg, gate_iterations, gate_paths)
    T = film["temporal_bins"]
    table.add(
        "one pass vs T passes",
        f"{T} gate frames in one pass",
        t_one,
        "s",
        note=f"median of 5 renders; {gate_iterations} iterations of {gate_paths} paths, {THREADS} threads",
    )
    table.add(
        "one pass vs T passes",
        f"{T} passes of one gate each",
        t_many,
        "s",
        note=f"largest frame difference {worst:.1e} of the peak",
    )
    table.add("one pass vs T passes", "speed-up", t_many / t_one, "x", ">= 32x", t_many / t_one >= 32)

    # 5. Scaling with threads.
    print("thread scaling ...", flush=True)
    load = load_average()
    repeats = 1 if quick else 3
    best, cpu, hashes = scaling(core, cfg, 4 if quick else 6, repeats)
    speedup = best[1] / best[THREADS]
    table.add("scaling", "1 thread", best[1], "s", note=f"best of {repeats}, bins mode; CPU time {cpu[1]:.2f} s")
    table.add(
        "scaling",
        f"{THREADS} threads",
        best[THREADS],
        "s",
        note=f"CPU time {cpu[THREADS]:.2f} s; load average before the runs {load}",
    )
    table.add(
        "scaling",
        "speed-up",
        speedup,
        "x",
        ">= 1.8x",
        speedup >= 1.8,
        note="bit-identical images" if hashes[1] == hashes[THREADS] else "IMAGES DIFFER",
    )

    # 6. Peak memory, one process per configuration.
    print("memory ...", flush=True)
    # The first run holds one light path and a one-frame film: its growth is the render's fixed cost
    # (the compiled scene: mesh copies and its Embree BVH; threads), which no film or beam size changes.
    specs = [
        {"frames": 1, "paths": 1, "iterations": 1},
        {"frames": T, "paths": cfg.light_paths_per_iteration, "iterations": 2},
        {"frames": 512, "paths": cfg.light_paths_per_iteration, "iterations": 2},
        {"frames": 16, "paths": 400_000, "iterations": 2},
    ]
    fixed, *measured = memory(specs)
    scene_bytes = fixed["peak"] - fixed["rss_before"]
    table.add(
        "memory",
        "fixed cost of a render (compiled scene, threads)",
        f"{scene_bytes / 2**20:.1f} MiB",
        "",
        note="peak RSS growth of a render of 1 light path into a 1-frame film",
    )
    for m in measured:
        used = m["peak"] - m["rss_before"]
        budget = m["frame_buffer"] + m["beam_storage"]
        ratio, beyond = used / budget, (used - scene_bytes) / budget
        table.add(
            "memory",
            f"{m['frames']} frames, {m['paths']} paths/iteration",
            f"{used / 2**20:.0f} MiB",
            "",
            "<= 1.5x",
            beyond <= 1.5,
            note=f"{beyond:.2f}x of frames {m['frame_buffer'] / 2**20:.1f} MiB (float32) + beams "
            f"{m['beam_storage'] / 2**20:.1f} MiB ({m['beams_per_iteration']:.0f} x {BEAM_BYTES} B) beyond the "
            f"fixed cost, {ratio:.2f}x with it; BVH {m['accel_references']:.0f} pieces (32 B each); "
            f"peak RSS {m['peak'] / 2**20:.0f} MiB, {m['rss_before'] / 2**20:.0f} MiB before the render",
        )

    table.add(
        "setup",
        "bench time",
        f"{time.perf_counter() - run.clock:.0f} s",
        "",
        note=f"load average at the end {load_average()}",
    )
    text = table.markdown()
    print("\n" + text)
    figure = (LOCAL if quick else RESULTS) / "ptpb_error_vs_time.png"
    figure.parent.mkdir(parents=True, exist_ok=True)
    reach = lambda curve, ours: curve.seconds_for(ours[-1][1])[1]  # noqa: E731  (spp to our final error)
    plot(
        figure,
        {
            "ours (PTPB, bins)": ([(t, e) for t, e, _ in ours_t], "o-"),
            "mitransient, this run": (mitr.curve(), "s-"),
            "mitransient, expected V/n": (mitr.expected_curve(reach(mitr, ours_t)), "--"),
        },
        {
            "ours (PTPB, steady)": ([(t, e) for t, e, _ in ours_s], "o-"),
            "volpath, this run": (volpath.curve(), "s-"),
            "volpath, expected V/n": (volpath.expected_curve(reach(volpath, ours_s)), "--"),
            "prbvolpath, this run": (prb.curve(), "^-"),
            "prbvolpath, expected V/n": (prb.expected_curve(reach(prb, ours_s)), ":"),
        },
    )
    write_results("ptpb", text, run, rows=table.rows, standard=not quick)
    print(f"wrote {figure.relative_to(REPO)}")


if __name__ == "__main__":
    main()
