"""Ray-engine throughput: 1M rays against a 1M-triangle height-field mesh, on 1 and 2 threads.

Run with `make bench` (or `.venv/bin/python benchmarks/bench_rays.py`). Prints a table and writes
benchmarks/results/rays.md and .csv.
"""

from __future__ import annotations

import time

import numpy as np
from _results import start, write_results

from render.engine import RayEngine


def rough_terrain(cells_per_side: int, size_m: float = 10.0, seed: int = 0):
    """A rough height field triangulated into 2 * cells_per_side**2 triangles."""
    rng = np.random.default_rng(seed)
    n = cells_per_side + 1
    x, y = np.meshgrid(np.linspace(0, size_m, n), np.linspace(0, size_m, n), indexing="xy")
    z = 0.5 * np.sin(3.1 * x) * np.cos(2.3 * y) + 0.05 * rng.standard_normal((n, n))
    vertices = np.stack([x, y, z], axis=-1).reshape(-1, 3).astype(np.float32)
    i, j = np.meshgrid(np.arange(cells_per_side), np.arange(cells_per_side), indexing="ij")
    v00 = (i * n + j).ravel()
    v01, v10, v11 = v00 + 1, v00 + n, v00 + n + 1
    faces = np.concatenate([np.stack([v00, v01, v11], 1), np.stack([v00, v11, v10], 1)]).astype(np.uint32)
    return vertices, faces


def main() -> None:
    run = start()
    ray_count = 1_000_000
    vertices, faces = rough_terrain(708)  # 2 * 708^2 = 1.00M triangles
    engine = RayEngine()
    t0 = time.perf_counter()
    engine.add_mesh(vertices, faces, mesh_id=0)
    engine.commit()
    build_s = time.perf_counter() - t0
    rng = np.random.default_rng(1)
    origins = np.column_stack([rng.uniform(0, 10, ray_count), rng.uniform(0, 10, ray_count), np.full(ray_count, 3.0)])
    directions = rng.normal(size=(ray_count, 3))
    directions[:, 2] = -np.abs(directions[:, 2]) - 0.5
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    origins, directions = origins.astype(np.float32), directions.astype(np.float32)
    rows = []
    reference = None
    for threads in (1, 2):
        for query in ("intersect", "occluded"):
            fn = getattr(engine, query)
            fn(origins[:10000], directions[:10000], threads=threads)  # warm-up
            t0 = time.perf_counter()
            result = fn(origins, directions, threads=threads)
            seconds = time.perf_counter() - t0
            if query == "intersect":
                if reference is None:
                    reference = result.t
                elif not np.array_equal(reference, result.t):
                    raise SystemExit("thread count changed the intersection results")
            rows.append(
                {
                    "query": query,
                    "threads": threads,
                    "rays": ray_count,
                    "triangles": engine.triangle_count,
                    "seconds": round(seconds, 3),
                    "mrays_per_s": round(ray_count / seconds / 1e6, 2),
                }
            )
    for query in ("intersect", "occluded"):
        one, two = (r for r in rows if r["query"] == query)
        two["speedup"] = round(one["seconds"] / two["seconds"], 2)
        one["speedup"] = 1.0
    header = ["query", "threads", "rays", "triangles", "seconds", "mrays_per_s", "speedup"]
    lines = [
        f"Embree BVH build for {engine.triangle_count:,} triangles: {build_s:.2f} s",
        "",
        "| " + " | ".join(header) + " |",
        "|" + "---|" * len(header),
    ]
    lines += ["| " + " | ".join(str(r[h]) for h in header) + " |" for r in rows]
    table = "\n".join(lines) + "\n"
    print(table)
    write_results("rays", table, run, rows=rows)


if __name__ == "__main__":
    main()
