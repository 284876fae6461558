"""Laser altimetry over snow (issue 29): diffusion theory of the pulse in the snow, pulses and range estimators,
single-wavelength snow optics (LIDAR.md). Pure numpy/scipy; it never needs the compiled core."""
