"""vecontact: viscoelastic steady sliding contact of rough surfaces.

Persson's mean-field theory and the exact numerical solution, MPI-parallel.
Conventions (SI units, Fourier, PSD, modulus sign, friction) follow docs/conventions.md.

The Python API (``import vecontact as vc``; docs/api.md) lives in :mod:`vecontact.api`; its names
are loaded on first use, so ``import vecontact`` (and the command line) stays light.
"""
__version__ = "0.1.0"

_API = ("load_job", "make_job", "Job", "run", "read_results", "plot_results", "surface", "read_topography",
        "read_psd", "self_affine", "modulus", "theory", "solve", "Surface", "Theory", "InputError",
        "InputWarning", "ConvergenceWarning", "REFERENCE_COMPOUND")

__all__ = ["__version__", *_API]


def __getattr__(name):
    if name in _API:
        from vecontact import api
        return getattr(api, name)
    raise AttributeError(f"module 'vecontact' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_API))
