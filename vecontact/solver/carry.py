"""The directions an exact contact-set step carries over from the step before it.

An exact Newton step (policy.py: the active set did not change) solves the same linear system as the
step before it, and its right-hand side is that step's inner residual: the Newton residual is affine
on a fixed active set.  Restarting the Krylov solve from that residual throws away the space the
last step had built, and the new solve spends its first iterations finding the slow directions again.
So the last step's preconditioned vectors Z and their products A Z, known without an FFT pair from
its Arnoldi relation A Z = V G (single.py, ``SingleGMRES.arnoldi``), start the exact step's FGMRES:
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

__all__ = ["CarriedDirections"]

# entries of the carried products formed at a time (a float32 block of the last step's basis)
_BLOCK = 1 << 16


class CarriedDirections:
    """The last ``count`` preconditioned vectors of a flexible SingleGMRES solve's last cycle (``U``,
    copies in the work dtype) and their products (``AU``, float32), handed to a PETSc FGMRES one
    pair at a time: ``serve_direction(y)`` in place of the preconditioner, ``serve_product(y)`` in
    place of the operator's product that follows it.  ``served``: directions handed out so far."""

    def __init__(self, gmres, count):
        k, G = gmres.arnoldi
        m = min(int(count), k)
        cols = slice(k - m, k)
        self.U = gmres.Z[cols].copy()
        n = self.U.shape[1]
        self.AU = np.empty((m, n), dtype=np.float32)
        Gt = np.ascontiguousarray(G[:, cols].T, dtype=np.float32)
        V = gmres.V[:k + 1]
        for s in range(0, n, _BLOCK):        # A Z[j] = sum_i G[i, j] V[i]
            e = min(s + _BLOCK, n)
            np.matmul(Gt, V[:, s:e], out=self.AU[:, s:e])
        self.served = 0
        self._pending = None

    @staticmethod
    def count(n_loc, work_itemsize, directions, memory):
        """How many directions to carry: at most ``directions``, within ``memory`` bytes a rank (a copy
        of each in the work dtype and its float32 product, ``n_loc`` entries each)."""
        per = max(int(n_loc), 1) * (work_itemsize + 4)
        return max(0, min(int(directions), int(memory // per)))

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
