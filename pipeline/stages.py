"""The pipeline's stages, in order: geometry -> scene -> reference, render -> composite -> compare, and
geometry -> lidar for a laser altimeter's run (``lidar.enabled``), which renders no camera view.

Each stage is a plain function of a StageContext that calls one function of geometry/ or render/.
Heavy modules are imported inside the functions so that `python -m pipeline validate` stays fast.
"""

from __future__ import annotations

from pipeline.runner import Stage, StageContext
from pipeline.space import film_bytes, image_bytes


def geometry_stage(ctx: StageContext) -> dict:
    from geometry.stage import run_geometry_stage

    return run_geometry_stage(ctx.config.geometry, ctx.out_dir, seed=ctx.config.field_seed(), quiet=ctx.quiet)


def _uses_penitentes(config) -> bool:
    if config.lidar.enabled:
        return config.lidar.target == "penitentes"
    return any(o.shape == "penitentes" for o in config.scene.objects)


def _views(config) -> bool:
    """The camera's chain (scene -> compare) runs unless the run is a lidar shot."""
    return not config.lidar.enabled


def scene_stage(ctx: StageContext) -> dict:
    from render.scene.stage import run_scene_stage

    g = ctx.config.geometry
    site = {"latitude": g.latitude, "day_of_year": g.start_day_of_year + g.days - 1}
    return run_scene_stage(ctx.config.scene, ctx.out_dir, geometry_dir=ctx.inputs.get("geometry"), site=site)


def reference_stage(ctx: StageContext) -> dict:
    from render.mitsuba.stage import run_reference_stage

    return run_reference_stage(
        ctx.inputs["scene"], ctx.config.reference, ctx.out_dir, seed=ctx.config.seed, quiet=ctx.quiet
    )


def reference_writes(config) -> int:
    """The reference's large arrays: steady.npy and .exr; frames.npy, its EXR frames (counted uncompressed)
    and transient_steady.npy."""
    ref = config.reference
    steady = 2 * image_bytes(config) if ref.steady else 0
    transient = 2 * film_bytes(config) + image_bytes(config) if ref.transient else 0
    return steady + transient


def render_writes(config) -> int:
    """Our render's large arrays: frames.npy, steady.npy and .exr, snapshots.npz, and the checkpoint (the
    frame sums and six steady-sized float64 sums, twice while a new checkpoint replaces the last)."""
    r = config.render
    frames = 0 if r.frame_mode == "steady" else film_bytes(config)
    image = image_bytes(config)
    snapshots = r.iterations // r.snapshot_every * image if r.snapshot_every else 0
    checkpoint = 2 * (frames + 6 * image) if r.checkpoint_every_iterations or r.checkpoint_every_s else 0
    return frames + 2 * image + snapshots + checkpoint


def render_stage(ctx: StageContext) -> dict:
    from render.ptpb.stage import run_render_stage

    return run_render_stage(
        ctx.inputs["scene"],
        ctx.config.render_settings(),
        ctx.out_dir,
        quiet=ctx.quiet,
        checkpoint_dir=ctx.checkpoint_dir,
        shards=ctx.shards,
        shards_dir=ctx.shards_dir,
    )


def site_day(config) -> int:
    """The day of the year (1-365) that the scene is lit on: the last grown day."""
    g = config.geometry
    return (g.start_day_of_year + g.days - 2) % 365 + 1


def run_title(config) -> str:
    """A video title from the config: latitude, date and sun, e.g. 'Penitentes at 30.1°S, 3 Jan, sun at
    10:00 solar time: light in flight'."""
    from geometry.sunpath import calendar_day

    latitude = config.geometry.latitude
    site = f"{abs(latitude):.1f}°{'S' if latitude < 0 else 'N'}"
    sun = config.scene.sun
    if not sun.enabled:
        light = "no sun"
    elif sun.solar_time_h is not None:
        hours, minutes = divmod(round(sun.solar_time_h * 60), 60)
        light = f"sun at {hours:02d}:{minutes:02d} solar time"
    else:
        light = f"sun {sun.elevation_deg:g}° high"
    return f"Penitentes at {site}, {calendar_day(site_day(config))}, {light}: light in flight"


def composite_stage(ctx: StageContext) -> dict:
    from render.output.composite import run_composite_stage

    cfg = ctx.config.composite
    if cfg.title is None:
        cfg = cfg.model_copy(update={"title": run_title(ctx.config)})
    guides = None
    if cfg.denoise:
        from render.output.guides import guide_buffers

        guides = guide_buffers(ctx.inputs["scene"])
    return run_composite_stage(
        ctx.inputs["render"], ctx.inputs.get("reference"), ctx.inputs["scene"], cfg, ctx.out_dir, guides=guides
    )


def lidar_stage(ctx: StageContext) -> dict:
    from render.lidar.stage import run_lidar_stage

    c = ctx.config
    return run_lidar_stage(
        c.lidar, ctx.out_dir, geometry_dir=ctx.inputs.get("geometry"), seed=c.seed, threads=c.threads, quiet=ctx.quiet
    )


def compare_stage(ctx: StageContext) -> dict:
    from render.output.compare import run_compare_stage

    run_root = ctx.out_dir.parent
    return run_compare_stage(
        run_root,
        ctx.inputs["render"],
        ctx.inputs.get("reference"),
        ctx.out_dir,
        [s.name for s in STAGES],
        f"Run '{ctx.config.name}'",
    )


STAGES: list[Stage] = [
    Stage(
        "geometry",
        geometry_stage,
        ("geometry", "seed"),
        description="grow the penitente field, mesh it watertight, metrics and previews",
        enabled=_uses_penitentes,
    ),
    Stage(
        "scene",
        scene_stage,
        ("scene", "geometry.latitude", "geometry.start_day_of_year", "geometry.days"),
        upstream=("geometry",),
        description="the neutral scene description, meshes and the media's optical quantities",
        enabled=_views,
    ),
    Stage(
        "reference",
        reference_stage,
        ("reference", "seed"),
        upstream=("scene",),
        description="Mitsuba 3 volpath steady image and mitransient frames",
        enabled=lambda c: _views(c) and (c.reference.steady or c.reference.transient),
        writes=reference_writes,
    ),
    Stage(
        "render",
        render_stage,
        ("render", "seed", "threads", "scene.max_depth"),
        upstream=("scene",),
        description="our PTPB render: steady image, frames and statistics",
        enabled=_views,
        writes=render_writes,
    ),
    Stage(
        "composite",
        composite_stage,
        ("composite", "geometry.latitude", "geometry.start_day_of_year", "geometry.days", "scene.sun"),
        upstream=("render", "reference", "scene"),
        description="transient videos, streak images, ours against the reference",
        enabled=_views,
    ),
    Stage(
        "compare",
        compare_stage,
        ("composite",),
        upstream=("render", "reference", "composite"),
        description="comparison table, error-against-time plot and report.html",
        enabled=_views,
    ),
    Stage(
        "lidar",
        lidar_stage,
        ("lidar", "seed", "threads"),
        upstream=("geometry",),
        description="a laser altimeter's waveform over the field, its ranges and their biases",
        enabled=lambda c: c.lidar.enabled,
    ),
]
