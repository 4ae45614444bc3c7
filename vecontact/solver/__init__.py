"""Exact numerical solver: steady sliding contact of a viscoelastic half-space on a rigid rough surface.

    from vecontact.solver import solve_contact, ContactResult, SolverSettings
    res = solve_contact(fft, L, h, modulus, velocity, sigma0, tolerance=1e-8, method="snes")

Methods: "snes" (PETSc matrix-free semismooth Newton / primal-dual active set in the gap formulation,
any modulus, coarse-grid and previous-solution warm starts) and "pk" (Polonsky-Keer constrained CG,
elastic only, the baseline).  Module map:

* contact.py     solve_contact: coarse grids, warm starts, post-processing
* snes.py        the PETSc SNES set-up and callbacks of the semismooth Newton method
* newton.py      NewtonState: the iterate, its pressure and its active set
* policy.py      StepPolicy: where and how tightly each Newton step is solved (pure rules)
* measurestop.py MeasureStop: an exact step's Krylov solve ends once its update meets the SNES's test
* contactset.py, freeset.py   the two Newton-step solvers (on the contact set, on the free set);
  subset.py: what they share
* vi.py          -snes_type vinewtonrsls (PETSc's reduced-space VI Newton), the alternative
* pk.py          Polonsky-Keer; operator.py: the nondimensional operator; warmstart.py: grid transfers
* settings.py    SolverSettings, every tuning constant; options.py: the one PETSc-options parser
* result.py      ContactResult and the scalars (area, mu, ...)

The package imports its MPI/PETSc parts on first use, so settings and options load without them.
"""
__all__ = ["solve_contact", "ContactResult", "SolverSettings"]


def __getattr__(name):
    if name == "solve_contact":
        from vecontact.solver.contact import solve_contact
        return solve_contact
    if name == "ContactResult":
        from vecontact.solver.result import ContactResult
        return ContactResult
    if name == "SolverSettings":
        from vecontact.solver.settings import SolverSettings
        return SolverSettings
    raise AttributeError(f"module 'vecontact.solver' has no attribute {name!r}")
