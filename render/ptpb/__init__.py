"""Our PTPB renderer from Python: ``render(scene, settings)``, its settings, checkpoints and stage.

The public API is re-exported here (``from render.ptpb import render``); the compiled core is the
private module ``render._core``."""

from render.engine import load_core_scene as load_scene
from render.ptpb.api import RenderResult, core_inputs, memory_bytes, render, resolve_settings, scene_bounding_sphere

__all__ = [
    "RenderResult",
    "core_inputs",
    "load_scene",
    "memory_bytes",
    "render",
    "resolve_settings",
    "scene_bounding_sphere",
]
