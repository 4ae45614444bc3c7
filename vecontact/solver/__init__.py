"""Exact numerical solver: steady sliding contact of a viscoelastic half-space on a rigid rough surface.

    from vecontact.solver import solve_contact, ContactResult
    res = solve_contact(fft, L, h, modulus, velocity, sigma0, tolerance=1e-8, method="snes")

Methods: "snes" (PETSc matrix-free semismooth Newton / primal-dual active set in the gap formulation,
any modulus, coarse-grid and previous-solution warm starts) and "pk" (Polonsky-Keer constrained CG,
elastic only, the baseline).  See contact.py, snes.py, pk.py, operator.py, result.py, warmstart.py.
"""
from vecontact.solver.result import ContactResult
from vecontact.solver.contact import solve_contact

__all__ = ["solve_contact", "ContactResult"]
