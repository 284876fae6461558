"""The scene of one lidar shot for the PTPB core (render/lidar/LIDAR.md §7.1).

Transport in snow behind index-matched faces is reciprocal, its clock (the medium's group index) included,
so the shot is rendered backwards: the receiver, which sees the whole footprint with a uniform response,
becomes a plane wave from its direction (a sun of unit irradiance pinned to the reference plane), and the
laser becomes an orthographic camera over the footprint, looking along the beam. A pixel then holds the
light that a pencil of the laser at that point returns to the receiver, and the footprint's Gaussian
weights the pixels afterwards (``receiver_weights``), so one render serves any footprint that fits on its
film. Both time origins lie on the reference plane z = ``reference_height``: light turned back by a surface d
below it arrives at OPL 2d, range d; each metre of path in snow of group index n adds n metres of OPL.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from render.scene.shapes import box_mesh

Target = Literal["penitentes", "flat_snow", "bare"]
# A snow solid's faces: index matched, medium 0 inside, the vacuum outside.
_SNOW_FACES: dict[str, Any] = {"kind": "null", "interior": 0, "exterior": -1}


@dataclass(frozen=True)
class Receiver:
    """The film of a shot: ``pixels`` x ``pixels`` over a square of side ``side`` [m] centred at ``centre``
    (x, y) on the reference plane z = ``reference_height``; bins of ``bin_width_opl`` [m] from OPL 0."""

    centre: tuple[float, float]
    side: float
    pixels: int
    reference_height: float
    bin_width_opl: float
    temporal_bins: int

    def pixel_centres(self) -> tuple[np.ndarray, np.ndarray]:
        """World x (columns, growing with the column) and y (rows, falling with the row) of pixel centres."""
        offsets = ((np.arange(self.pixels) + 0.5) / self.pixels - 0.5) * self.side
        return self.centre[0] + offsets, self.centre[1] - offsets

    def camera(self) -> dict[str, Any]:
        """The laser, reversed: an orthographic camera looking straight down from the reference plane."""
        cx, cy, z = self.centre[0], self.centre[1], self.reference_height
        return {
            "origin": (cx, cy, z),
            "target": (cx, cy, z - 1.0),
            "up": (0.0, 1.0, 0.0),
            "projection": "orthographic",
            "ortho_width": self.side,
            "width": self.pixels,
            "height": self.pixels,
        }

    def receiver_light(self) -> dict[str, Any]:
        """The receiver, reversed: a zenith plane wave of unit irradiance whose tau = 0 plane is the reference
        plane."""
        cx, cy, z = self.centre[0], self.centre[1], self.reference_height
        return {"to_sun": (0.0, 0.0, 1.0), "irradiance": (1.0, 1.0, 1.0), "reference_point": (cx, cy, z)}

    def film(self) -> dict[str, Any]:
        return {
            "frame_mode": "bins",
            "temporal_bins": self.temporal_bins,
            "start_opl": 0.0,
            "bin_width_opl": self.bin_width_opl,
        }


def receiver_weights(receiver: Receiver, diameter: float, centre: tuple[float, float] | None = None) -> np.ndarray:
    """A Gaussian footprint of 1/e² ``diameter`` [m] (irradiance ∝ exp(-8 r²/D²)) at the receiver's pixel
    centres, normalised to sum to 1: (pixels, pixels), rows as the film's. Refuses a footprint whose 1/e²
    circle leaves the film (its weight there would be lost)."""
    if not diameter > 0:
        raise ValueError(f"lidar footprint diameter must be positive, got {diameter} m")
    cx, cy = receiver.centre if centre is None else centre
    reach = max(abs(cx - receiver.centre[0]), abs(cy - receiver.centre[1])) + diameter / 2
    if reach > receiver.side / 2:
        raise ValueError(
            f"a footprint of {diameter} m at {(cx, cy)} reaches {reach:.3g} m from the film's centre, beyond its "
            f"half side {receiver.side / 2:.3g} m; widen the receiver film (lidar.film_side_footprints)"
        )
    xs, ys = receiver.pixel_centres()
    r2 = (xs[None, :] - cx) ** 2 + (ys[:, None] - cy) ** 2
    w = np.exp(-8.0 * r2 / diameter**2)
    return w / w.sum()


def medium(sigma_s: Sequence[float], sigma_a: Sequence[float], g: float, group_index: float = 1.0) -> dict[str, Any]:
    """A medium of the core with per-channel coefficients [1/m] (three of each) behind index-matched faces, whose
    clock runs at ``group_index``: light takes group_index/c per metre of path (``optics.snow_group_index``; 1 is
    light at c). Behind ``null`` faces the core reads ``ior`` for time alone, never for refraction."""
    if len(sigma_s) != 3 or len(sigma_a) != 3:
        raise ValueError(f"a medium needs three sigma_s and three sigma_a, got {sigma_s} and {sigma_a}")
    if not (math.isfinite(group_index) and group_index >= 1):
        raise ValueError(f"a medium's group index must be at least 1 (1: light at c), got {group_index}")
    return {
        "sigma_s": tuple(map(float, sigma_s)),
        "sigma_a": tuple(map(float, sigma_a)),
        "g": float(g),
        "ior": float(group_index),
    }


def shot_scene(
    target: Target,
    receiver: Receiver,
    *,
    snow: dict[str, Any] | None = None,
    mesh: tuple[np.ndarray, np.ndarray] | None = None,
    bare_albedo: float = 0.5,
    depth: float = 2.0,
) -> dict[str, Any]:
    """The core dict of a shot at ``target``: the grown field's solid ``mesh`` filled with ``snow`` (a medium
    dict), flat snow (a box ``depth`` deep under z = 0, twice the film's side wide) or a bare Lambertian
    surface of albedo ``bare_albedo`` at z = 0."""
    if target == "penitentes":
        if mesh is None or snow is None:
            raise ValueError("a penitente shot needs the field's mesh and the snow medium")
        vertices, faces = mesh
        shape = {"vertices": vertices, "faces": faces, **_SNOW_FACES}
        media = [snow]
    elif target == "flat_snow":
        if snow is None:
            raise ValueError("a flat-snow shot needs the snow medium")
        shape = {**_box(receiver, receiver.side, depth), **_SNOW_FACES}
        media = [snow]
    elif target == "bare":
        if not 0 < bare_albedo <= 1:
            raise ValueError(f"lidar.bare_albedo must lie in (0, 1], got {bare_albedo}")
        shape = {**_box(receiver, receiver.side, depth), "kind": "diffuse", "albedo": (bare_albedo,) * 3}
        media = []
    else:
        raise ValueError(f"unknown lidar target '{target}': use penitentes, flat_snow or bare")
    return {
        "media": media,
        "shapes": [shape],
        "directional_lights": [receiver.receiver_light()],
        "camera": receiver.camera(),
        "film": receiver.film(),
    }


def _box(receiver: Receiver, half_width: float, depth: float) -> dict[str, Any]:
    """The mesh of a box ``half_width`` on each side of the receiver's centre and ``depth`` deep under z = 0."""
    cx, cy = receiver.centre
    v, f = box_mesh((cx - half_width, cy - half_width, -depth), (cx + half_width, cy + half_width, 0.0))
    return {"vertices": v, "faces": f}


def bins_for(opl_span: float, bin_width_opl: float) -> int:
    """The number of bins of ``bin_width_opl`` that cover ``opl_span`` [m]."""
    if not bin_width_opl > 0:
        raise ValueError(f"bin width must be positive, got {bin_width_opl} m")
    return max(1, math.ceil(opl_span / bin_width_opl))


def flux_scene(
    receiver: Receiver,
    snow: dict[str, Any],
    *,
    depth: float,
    half_width: float,
    rings: Sequence[tuple[float, float]] | None = None,
    gap: float = 5e-5,
    segments: int = 128,
) -> dict[str, Any]:
    """Flat snow under the orthographic receiver, lit by Lambertian emitters of unit radiance that face down
    from ``gap`` above the snow (render/lidar/LIDAR.md §7.6). By reciprocity a pixel at x holds the flux that a
    nadir pencil entering at x sends back up through the emitters' area, over all directions.

    Without ``rings`` one square emitter as wide as the snow, in every channel, gives the area-integrated R(t)
    of diffusion theory. With ``rings`` [(inner, outer), ...] (at most three, radii in metres about the
    receiver's centre; inner 0 for a disk) ring k emits in channel k only, so one render holds R(ρ, t)
    integrated over up to three rings. The snow is a box ``half_width`` on each side of the centre and
    ``depth`` deep under z = 0; camera rays cross the emitters from behind, where they neither emit nor stop
    them (null faces)."""
    if not 0 < gap < receiver.reference_height:
        raise ValueError(f"the emitter's gap {gap} m must lie between the snow and the reference plane")
    cx, cy = receiver.centre
    shapes: list[dict[str, Any]] = [{**_box(receiver, half_width, depth), **_SNOW_FACES}]
    if rings is None:
        corners = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]]) * half_width
        shapes.append(_emitter(_fan(corners), (cx, cy), gap, (1.0, 1.0, 1.0)))
    else:
        if not 1 <= len(rings) <= 3:
            raise ValueError(f"flux_scene takes one to three rings (one per channel), got {len(rings)}")
        angles = 2 * np.pi * np.arange(segments) / segments
        unit = np.stack([np.cos(angles), np.sin(angles)], axis=1)
        for k, (inner, outer) in enumerate(rings):
            if not 0 <= inner < outer < half_width:
                raise ValueError(f"ring {k}: radii ({inner}, {outer}) m must satisfy 0 <= inner < outer < {half_width}")
            radiance = tuple(1.0 if c == k else 0.0 for c in range(3))
            mesh = _fan(outer * unit) if inner == 0 else _annulus(inner * unit, outer * unit)
            shapes.append(_emitter(mesh, (cx, cy), gap, radiance))
    return {"media": [snow], "shapes": shapes, "camera": receiver.camera(), "film": receiver.film()}


def _fan(outline: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A convex outline (n, 2), counter-clockwise, as a fan about the origin wound to face down."""
    n = len(outline)
    vertices = np.vstack([np.zeros((1, 2)), outline])
    faces = np.array([[0, 1 + (i + 1) % n, 1 + i] for i in range(n)])
    return vertices, faces


def _annulus(inner: np.ndarray, outer: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The band between two counter-clockwise outlines of n points each, wound to face down."""
    n = len(inner)
    faces = []
    for i in range(n):
        j = (i + 1) % n
        faces += [[i, n + j, n + i], [i, j, n + j]]
    return np.vstack([inner, outer]), np.array(faces)


def _emitter(
    mesh: tuple[np.ndarray, np.ndarray], centre: tuple[float, float], height: float, radiance: tuple[float, ...]
) -> dict[str, Any]:
    xy, faces = mesh
    vertices = np.column_stack([xy[:, 0] + centre[0], xy[:, 1] + centre[1], np.full(len(xy), height)])
    return {
        "vertices": vertices.astype(np.float32),
        "faces": faces.astype(np.uint32),
        "kind": "null",
        "interior": -1,
        "exterior": -1,
        "radiance": radiance,
    }
