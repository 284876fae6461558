"""The config schema: the root model composed of one section per stage."""

from __future__ import annotations

from typing import Any

from pydantic import (
    Field,
    SerializationInfo,
    SerializerFunctionWrapHandler,
    field_validator,
    model_serializer,
    model_validator,
)

from pipeline.schema.base import StrictModel
from pipeline.schema.composite import CompositeConfig
from pipeline.schema.geometry import GeometryConfig
from pipeline.schema.lidar import LidarConfig
from pipeline.schema.ptpb import PTPBConfig
from pipeline.schema.scene import ReferenceConfig, SceneConfig

# Keys of the render section whose single home in a pipeline config is elsewhere.
BORROWED_RENDER_KEYS = {
    "seed": "seed",
    "threads": "threads",
    "max_depth": "scene.max_depth",
}


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
        description="The render stage: our PTPB renderer (seed and threads come from the root, the path depth "
        "from scene.max_depth).",
    )
    composite: CompositeConfig = Field(
        default_factory=CompositeConfig,
        description="The composite and compare stages: videos, streaks, figures, tables.",
    )
    lidar: LidarConfig = Field(
        default_factory=LidarConfig,
        description="The lidar stage: a laser altimeter's waveform and range biases over the field.",
    )

    def field_seed(self) -> int:
        """The grown field's seed: geometry.seed, or the run's seed when it is unset."""
        return self.seed if self.geometry.seed is None else self.geometry.seed

    def render_settings(self) -> PTPBConfig:
        """The render section with the keys it takes from elsewhere: the root's seed and threads, and the
        path depth of the scene, which the references render with too."""
        return self.render.model_copy(
            update={
                "seed": self.seed,
                "threads": self.threads,
                "max_depth": self.scene.max_depth,
            }
        )

    @model_serializer(mode="wrap")
    def _without_borrowed_keys(self, handler: SerializerFunctionWrapHandler, info: SerializationInfo) -> Any:
        # A dump validates again: the render keys that live elsewhere are left out of it.
        data = handler(self)
        if isinstance(data, dict) and isinstance(data.get("render"), dict):
            data["render"] = {k: v for k, v in data["render"].items() if k not in BORROWED_RENDER_KEYS}
        return data

    @field_validator("render")
    @classmethod
    def _one_home_per_key(cls, render: PTPBConfig) -> PTPBConfig:
        # The render stage takes these from where every stage reads them; a value under render: would be
        # silently replaced, so it is refused instead.
        for key, home in BORROWED_RENDER_KEYS.items():
            if key in render.model_fields_set:
                raise ValueError(
                    f"render.{key} cannot be set in a pipeline config: set `{home}` instead, which the render "
                    "stage reads (so that ours and the reference use the same value)"
                )
        return render

    @model_validator(mode="after")
    def _reference_film_divides(self) -> Config:
        k, camera = self.reference.downsample, self.scene.camera
        if k > 1 and (camera.width % k or camera.height % k):
            raise ValueError(
                f"reference.downsample = {k} must divide scene.camera.width ({camera.width}) and "
                f"scene.camera.height ({camera.height}): the references' pixels are {k} x {k} blocks of ours. "
                "Pick a film size that is a multiple of it, or a downsample that divides both"
            )
        return self


__all__ = ["Config", "StrictModel"]
