"""vecontact: viscoelastic steady sliding contact of rough surfaces.

Persson's mean-field theory and the exact numerical solution, MPI-parallel.
Conventions (SI units, Fourier, PSD, modulus sign, friction) follow CONVENTIONS.md.
"""
__version__ = "0.1.0"
