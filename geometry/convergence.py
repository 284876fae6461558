"""Grid convergence of a grown field's numbers (DESIGN.md 7, *Grid convergence*): Richardson extrapolation
from three grids that each halve the cell, and the relative error of each grid against the extrapolated value.
Pure functions; the study itself is benchmarks/grid_convergence.py."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# Orders are measured when the three values converge monotonically; otherwise first order is assumed, the
# cautious choice: the minmod slopes are second order on smooth surfaces but first at extrema (DESIGN.md 6.1).
SCHEME_ORDER = 1.0


@dataclass(frozen=True)
class Richardson:
    """Extrapolated value at zero cell size, the order used, and whether it was measured."""

    extrapolated: float
    order: float
    order_measured: bool


def richardson(coarse: float, medium: float, fine: float, refinement: float = 2.0) -> Richardson:
    """Richardson extrapolation of f(cell) = f0 + c cell^p from three grids whose cells shrink by ``refinement``.

    The order p = log((f_medium - f_coarse) / (f_fine - f_medium)) / log(refinement) is measured when the two
    differences share a sign and shrink (monotone convergence), and kept within [0.5, 4]; otherwise the
    first order is assumed and flagged. f0 = f_fine + (f_fine - f_medium) / (refinement^p - 1)."""
    first, second = medium - coarse, fine - medium
    if second == 0.0:
        return Richardson(float(fine), SCHEME_ORDER, first == 0.0)
    measured = first * second > 0 and abs(second) < abs(first)
    order = float(np.clip(np.log(first / second) / np.log(refinement), 0.5, 4.0)) if measured else SCHEME_ORDER
    return Richardson(float(fine + second / (refinement**order - 1.0)), order, measured)


def relative_error(value: float, reference: float) -> float:
    """|value - reference| / |reference| [-]."""
    return abs(value - reference) / abs(reference)
