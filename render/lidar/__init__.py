"""Laser altimetry over snow (issues 29 and 51): diffusion theory of the pulse in the snow, pulses and range
estimators, single-wavelength snow optics and the snow's clock, photon counting with an ATL06-like surface finder,
grain-size retrieval, and a packing of ice spheres traced exactly (LIDAR.md). The analysis modules are pure
numpy/scipy; the renders (scene, stage, retrieval's table) and grains.py's tracer call the compiled core."""
