"""The config schema: the root model composed of one section per stage."""

from __future__ import annotations

from pydantic import Field

from pipeline.schema.base import StrictModel
from pipeline.schema.composite import CompositeConfig
from pipeline.schema.geometry import GeometryConfig
from pipeline.schema.ptpb import PTPBConfig
from pipeline.schema.scene import ReferenceConfig, SceneConfig


class Config(StrictModel):
    """A whole pipeline run. Each stage reads only the sections it declares."""

    name: str = Field(
        description="Run name; outputs go to runs/<name>/. Defaults to the config file's stem.",
        pattern=r"^[A-Za-z0-9][A-Za-z0-9_.-]*$",
        max_length=120,
    )
    seed: int = Field(1, ge=0, le=2**63 - 1, description="Seed of every random stream of the run [-].")
    threads: int = Field(0, ge=0, le=1024, description="Worker threads for the C++ core; 0 uses every core [-].")
    runs_dir: str = Field(
        "runs", min_length=1, description="Folder that holds run outputs, relative to the working directory [path]."
    )
    geometry: GeometryConfig = Field(
        default_factory=GeometryConfig, description="The geometry stage: growing and meshing the field."
    )
    scene: SceneConfig = Field(
        default_factory=SceneConfig, description="The scene stage: camera, lights, media, objects, film."
    )
    reference: ReferenceConfig = Field(
        default_factory=ReferenceConfig, description="The reference stage: Mitsuba 3 volpath and mitransient."
    )
    render: PTPBConfig = Field(
        default_factory=PTPBConfig,
        description="The render stage: our PTPB renderer (seed and threads come from the root).",
    )
    composite: CompositeConfig = Field(
        default_factory=CompositeConfig,
        description="The composite and compare stages: videos, streaks, figures, tables.",
    )


__all__ = ["Config", "StrictModel"]
