"""Settings of our Progressive Transient Photon Beams renderer (render/core/DESIGN.md §6 "Proposed keys").

Each setting is declared once, in the core: render/core/include/ptpb/settings.hpp gives its key, default,
bounds, choices and description (RenderSettings, for_each_setting), which render._core.render_settings_spec()
reports. PTPBConfig has one field per setting a config sets, built from that list in its order. The keys
with a shape of their own are declared here: the kernel radii and T_0 in the user's units (resolved to metres
in render/ptpb/settings.py) and frame_mode, which goes into the core's scene. tests/render/ptpb/test_settings_home.py
keeps the two sides equal."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Literal

from pydantic import Field, create_model
from pydantic.fields import FieldInfo

from pipeline.schema.base import StrictModel
from render import _core

CORE_SPEC = _core.render_settings_spec()
CORE_DEFAULTS: dict[str, Any] = {spec["key"]: spec["default"] for spec in CORE_SPEC}


class BeamRadius(StrictModel):
    """Initial spatial kernel radius (R_0 of the beams, r_0 of the surface photons) with an explicit unit."""

    value: float = Field(..., gt=0, description="The radius in the unit below [m | scene radii | pixel footprints].")
    unit: Literal["m", "scene_radius", "pixel_footprint"] = Field(
        "pixel_footprint",
        description="m: absolute; scene_radius: fraction of the scene's bounding radius; pixel_footprint: "
        "multiples of 2 z tan(fov/2) / P at the distance z from the camera to the scene centre [-].",
    )


class TimeHalfWidth(StrictModel):
    """Initial temporal kernel half-width T_0 (gate mode) with an explicit unit."""

    value: float = Field(..., gt=0, description="T_0 in the unit below [m OPL | bins | n R_0].")
    unit: Literal["m_opl", "bin_width", "beam_radius"] = Field(
        "beam_radius",
        description="m_opl: metres of optical path; bin_width: multiples of bin_width_opl; beam_radius: value * n * R_0 "
        "with n the largest medium index (value * n * r_0 for the surface photons' own T_0). A floor of "
        "bin_width_opl / 2 applies [-].",
    )


class _OwnKeys(StrictModel):
    """The render section's keys with a shape the core does not have."""

    initial_beam_radius: BeamRadius = Field(
        default_factory=lambda: BeamRadius(value=2.0, unit="pixel_footprint"),
        description="R_0, the initial 1D spatial kernel radius [see unit].",
    )
    initial_time_half_width: TimeHalfWidth = Field(
        default_factory=lambda: TimeHalfWidth(value=1.0, unit="beam_radius"),
        description="T_0, the initial temporal kernel half-width of gate mode [see unit].",
    )
    initial_surface_radius: BeamRadius = Field(
        default_factory=lambda: BeamRadius(value=2.0, unit="pixel_footprint"),
        description="r_0, the initial 2D disk kernel radius of the surface photons on diffuse surfaces (render/core/DESIGN.md §7) [see unit].",
    )
    frame_mode: Literal["steady", "bins", "gate"] | None = Field(
        None,
        description="What our frames hold: bins, integrals over each bin (as mitransient's, whose frames are always "
        "bins); gate, densities per metre of OPL at the bin centres, with the temporal kernel; steady, the steady "
        "image only. null: bins for a transient film, steady for a steady one (scene.film.mode) [-].",
    )


# An own key that is no core setting follows this core key, so that a dump (and the sweep point files written
# from one) keeps its order.
OWN_KEY_AFTER = {"frame_mode": "snapshot_every"}
_KIND_TYPES: dict[str, Any] = {"int": int, "float": float, "bool": bool, "optional": float | None}


def _core_field(spec: _core.RenderSettingSpec) -> tuple[Any, FieldInfo]:
    """The field of one core setting: its type from the kind, its default, bounds and description from the core."""
    annotation = Literal[tuple(spec["choices"] or ())] if spec["kind"] == "enum" else _KIND_TYPES[spec["kind"]]
    bounds: dict[str, Any] = {name: spec[name] for name in ("ge", "gt", "le", "lt") if spec[name] is not None}
    return annotation, Field(spec["default"], description=spec["description"], **bounds)


def _section_fields() -> dict[str, tuple[Any, FieldInfo]]:
    """The section's fields in order: each setting a config sets, in the core's order, an own key in place of
    the core's where it declares one."""
    own = {key: (field.annotation, field) for key, field in _OwnKeys.model_fields.items()}
    fields = {}
    for spec in CORE_SPEC:
        key = spec["key"]
        if key in own:
            fields[key] = own.pop(key)
        elif spec["config"]:
            fields[key] = _core_field(spec)
        fields |= {own_key: own.pop(own_key) for own_key, after in OWN_KEY_AFTER.items() if after == key}
    if own:
        raise RuntimeError(f"{sorted(own)} have no place in the render section: list each in OWN_KEY_AFTER")
    return fields


if TYPE_CHECKING:

    class PTPBConfig(_OwnKeys):
        # For mypy: the core settings that Python code reads by attribute, with their types. At run time every
        # setting a config sets is a field built from the core's declaration (below).
        iterations: int = CORE_DEFAULTS["iterations"]
        time_budget_s: float | None = CORE_DEFAULTS["time_budget_s"]
        camera_unwarp: bool = CORE_DEFAULTS["camera_unwarp"]
        checkpoint_every_iterations: int = CORE_DEFAULTS["checkpoint_every_iterations"]
        checkpoint_every_s: float | None = CORE_DEFAULTS["checkpoint_every_s"]
        memory_budget_gib: float | None = CORE_DEFAULTS["memory_budget_gib"]

else:
    PTPBConfig = create_model(
        "PTPBConfig",
        __base__=StrictModel,
        __module__=__name__,
        __doc__="Our PTPB renderer: light paths per iteration, bandwidth schedules, kernels and budgets.",
        **_section_fields(),
    )
