"""The core owns the schedule's defaults (render/core/DESIGN.md §6, issue 15): a direct render._core.ptpb_render
call without alpha, surface_alpha or the surfaces' bandwidths gets alpha* = 4/(d + 4) for its frame
mode and the fall-backs to R_0 and T_0, and reports what it used in its stats."""

from __future__ import annotations

import math

import pytest

from render import _core
from render.scene.shapes import box_mesh, quad_mesh

R0 = 0.03
ITERATIONS = 3


def scene(frame_mode: str) -> dict:
    """A 1 m box of medium under a 0.5 m area light, seen from 3 m, at 8 x 8 pixels."""
    cv, cf = box_mesh()
    lv, lf = quad_mesh(center=(0, 1.5, 0), u=(0.25, 0, 0), v=(0, 0, 0.25))
    return {
        "media": [{"sigma_s": (3.6, 5.4, 7.2), "sigma_a": (0.4, 0.6, 0.8), "g": 0.7}],
        "shapes": [
            {"vertices": cv, "faces": cf, "kind": "null", "interior": 0, "exterior": -1},
            {"vertices": lv, "faces": lf, "kind": "diffuse", "albedo": (0, 0, 0), "radiance": (20, 20, 20)},
        ],
        "camera": {"origin": (0, 0.8, math.sqrt(9 - 0.64)), "target": (0, 0, 0), "fov": 40, "width": 8, "height": 8},
        "film": {"frame_mode": frame_mode, "temporal_bins": 8, "start_opl": 3.5, "bin_width_opl": 0.1},
    }


def settings(**kw) -> dict:
    base = {"iterations": ITERATIONS, "light_paths_per_iteration": 200, "initial_beam_radius": R0, "seed": 1}
    base.update(kw)
    return base


@pytest.mark.parametrize("frame_mode, alpha, surface_alpha", [("gate", 2 / 3, 4 / 7), ("bins", 4 / 5, 2 / 3)])
def test_a_direct_core_call_gets_the_modes_alpha(frame_mode, alpha, surface_alpha):
    stats = _core.ptpb_render(scene(frame_mode), settings())["stats"]
    assert stats["alpha"] == pytest.approx(alpha, rel=1e-15)
    assert stats["surface_alpha"] == pytest.approx(surface_alpha, rel=1e-15)
    # The bandwidths of the last iteration follow that alpha: R = R_0 gamma^(1/2) in gate, R_0 gamma in bins.
    gamma = _core.ptpb_schedule_gamma(ITERATIONS - 1, alpha)
    expected = R0 * (math.sqrt(gamma) if frame_mode == "gate" else gamma)
    assert stats["final_radius"] == pytest.approx(expected, rel=1e-12)


def test_none_is_unset_and_explicit_values_win():
    unset = settings(alpha=None, surface_alpha=None, initial_surface_radius=None, initial_surface_time_half_width=None)
    stats = _core.ptpb_render(scene("gate"), unset)["stats"]
    assert stats["alpha"] == pytest.approx(2 / 3, rel=1e-15)
    assert stats["initial_beam_radius_m"] == R0
    assert stats["initial_time_half_width_m"] == R0  # T_0, r_0 and the surfaces' T_0 fall back to R_0
    assert stats["initial_surface_radius_m"] == R0
    assert stats["initial_surface_time_half_width_m"] == R0
    explicit = settings(alpha=0.9, surface_alpha=0.5, initial_time_half_width=0.05, initial_surface_radius=0.04)
    stats = _core.ptpb_render(scene("gate"), explicit)["stats"]
    assert (stats["alpha"], stats["surface_alpha"]) == (0.9, 0.5)
    assert (stats["initial_time_half_width_m"], stats["initial_surface_radius_m"]) == (0.05, 0.04)
    assert stats["initial_surface_time_half_width_m"] == 0.05  # the beams' T_0


def test_the_gate_default_renders_as_an_explicit_two_thirds():
    default = _core.ptpb_render(scene("gate"), settings())
    explicit = _core.ptpb_render(scene("gate"), settings(alpha=2 / 3))
    assert default["frames"].tobytes() == explicit["frames"].tobytes()
    assert default["frames"].sum() > 0
