"""The directions an exact contact-set step carries over from the step before it.

An exact Newton step (policy.py: the active set did not change) solves the same linear system as the
step before it, and its right-hand side is that step's inner residual: the Newton residual is affine
on a fixed active set.  Restarting the Krylov solve from that residual throws away the space the
last step had built, and the new solve spends its first iterations finding the slow directions again.
So the last step's directions (its preconditioned vectors Z, with their products A Z known without an
FFT pair from its Arnoldi relation A Z = V G, single.py, and the directions it carried itself,
recycle.py), orthonormalised in their products, start the exact step's FGMRES:
its first iterations take the carried z_j as their "preconditioned" vectors and A z_j from memory
(``Restricted`` asks ``serve_direction`` / ``serve_product``), then it goes on as usual.  FGMRES
minimises the residual over whatever vectors it is given, so this is the Krylov solve continued, as
GCRO's augmented space would be, with no FFT pair for the carried part.

The carried products are float32 (the last step's basis); their rounding only makes the
continuation a little less exact, never the answer: the Newton residual that judges the step is
formed in float64, and the measure stop (measurestop.py) reads the trial iterate itself.
Measurements: benchmarks/RESULTS.md, "`carry_directions`".
"""
from __future__ import annotations

import numpy as np

from vecontact.solver.single import project_out

__all__ = ["CarriedDirections"]


class CarriedDirections:
    """Directions ``U`` (rows) and their products ``AU`` (float32 rows, orthonormal), handed to a PETSc
    FGMRES one pair at a time: ``serve_direction(y)`` in place of the preconditioner, ``serve_product(y)``
    in place of the operator's product that follows it.  ``served``: directions handed out so far.

    Then ``start`` (the right-hand side less its part in span AU, float64) goes to the preconditioner once
    in place of FGMRES's own next vector (``next_input``), which is the last carried product: the
    Krylov space then grows from the residual, as GCRO's does (recycle.py), not from a carried
    direction.  ``of_space(space, fft, n_S, drop, b)``: those of a recycle.CarriedSpace for the right-hand
    side ``b``, orthonormalised (collective)."""

    def __init__(self, U, AU, start=None):
        self.U, self.AU = U, AU
        self.start = start
        self.served = 0
        self._pending = None

    @classmethod
    def of_space(cls, space, fft, n_S, drop, b):
        basis = space.basis(fft, n_S, drop)
        start = np.array(b, dtype=np.float64)
        project_out(basis.C, start, fft._allsum)
        return cls(basis.U, basis.C, start)

    def next_input(self, x):
        """What the preconditioner takes after the carried directions: ``start`` once, then ``x``."""
        if self.start is None or self.served < self.size:
            return x
        start, self.start = self.start, None
        return start

    @property
    def size(self):
        return self.U.shape[0]

    def serve_direction(self, y):
        """Put the next carried direction into ``y`` (a float64 array); False once all were served."""
        if self.served >= self.size:
            return False
        y[...] = self.U[self.served]
        self._pending = self.served
        self.served += 1
        return True

    def serve_product(self, y):
        """Put the product of the direction just served into ``y``; False when none is pending (the
        operator's product of another vector: a restart's residual)."""
        if self._pending is None:
            return False
        y[...] = self.AU[self._pending]
        self._pending = None
        return True
