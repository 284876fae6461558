"""The project's one speed of light in Python: time is optical path length in metres, and seconds =
OPL / c. The C++ core defines the same constant in render/core/include/ptpb/units.hpp, which the
bindings export; tests/render/output/test_composite.py checks that the two agree."""

from __future__ import annotations

SPEED_OF_LIGHT = 299_792_458.0  # m/s, exact
PS_PER_M_OPL = 1e12 / SPEED_OF_LIGHT  # 3335.640952 ps per metre of optical path
NS_PER_M_OPL = 1e9 / SPEED_OF_LIGHT  # 3.335640952 ns per metre of optical path
