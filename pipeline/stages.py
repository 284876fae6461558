"""The pipeline's stages, in order. Each stage is a plain function of a StageContext.

The stages of the full pipeline are geometry -> scene -> reference, render -> composite ->
compare; this list holds the ones that are implemented. Heavy modules are imported inside the
functions so that `python -m pipeline validate` stays fast.
"""
from __future__ import annotations

from pipeline.runner import Stage, StageContext


def geometry_stage(ctx: StageContext) -> dict:
    from geometry.stage import run_geometry_stage

    return run_geometry_stage(ctx.config.geometry, ctx.out_dir, seed=ctx.config.seed, quiet=ctx.quiet)


STAGES: list[Stage] = [
    Stage("geometry", geometry_stage, ("geometry", "seed"),
          description="grow the penitente field, mesh it watertight, metrics and previews"),
]
