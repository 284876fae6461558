"""Penitente fields grown from ablation physics, meshed as watertight solids (metres; x = east, y = north, z = up)."""
