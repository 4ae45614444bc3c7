"""NewtonState: the iterate of a Newton solve on one grid, its pressure and its active set.

Nondimensional (operator.py): the gap g^ in h_rms, the pressure p^(g^) = 1 + m (g^ + h^) in sigma0.
The active (contact) set of the semismooth method is C = {p^ >= kappa g^}, kappa = k h_rms / sigma0.
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI

from vecontact.solver.warmstart import smooth_gap

__all__ = ["NewtonState"]


class NewtonState:
    """Iterate g^, cached pressure p^(g^) and active set of the ContactOperator ``op`` (local rows).

    ``ensure(g)`` makes (g, p) the pressure of the iterate g (one FFT pair when g is new);
    ``update_active_set()`` moves to the active set of the current iterate and counts its changes;
    ``advance(x, s)`` moves to the Newton iterate g - x of a step whose pressure increment m x = s is
    known (contact-set steps), so that its residual costs no FFT pair; ``smooth_step(g0, x, ...)``
    smooths the iterate a step makes (free-set steps while the set changes, policy.py).
    """

    def __init__(self, op):
        self.op = op
        self.fft = op.fft
        self.comm = op.fft.comm
        self.shape = op.fft.local_real_shape
        self.kappa = op.kappa
        self.n_points = float(op.N) ** 2
        self.g = self.fft.real_array()     # the iterate whose pressure is cached
        self.p = self.fft.real_array()     # p^(g)
        self.valid = False                 # False until the first ensure()
        self.at_base = False               # (g, p) is the iterate of the current Jacobian (advance)
        self.act = np.zeros(self.shape, dtype=bool)
        self.nact = 0                      # points in act, all ranks
        self.updates = 0                   # update_active_set calls so far

    def view(self, vec, readonly=True):
        """A PETSc Vec of the grid as an array of the local rows."""
        return vec.getArray(readonly=readonly).reshape(self.shape)

    def ensure(self, g):
        """Make sure (self.g, self.p) is the iterate g (recompute p if not).  Collective: the ranks decide
        together, since the pressure takes an FFT pair and a step can leave one rank's rows unchanged
        (a full contact set's step changed only some rows: the ranks that skipped left the others
        waiting in the transform)."""
        same = self.valid and np.array_equal(g, self.g)
        if self.comm.size > 1:
            same = self.comm.allreduce(same, op=MPI.LAND)
        if same:
            return
        np.copyto(self.g, g)
        self.op.pressure(self.g, self.p)
        self.valid = True
        self.at_base = False

    def keep(self, g, p):
        """Make (g, p) the cached iterate: ``p`` is p^(g), computed elsewhere (measurestop.py)."""
        np.copyto(self.g, g)
        np.copyto(self.p, p)
        self.valid = True
        self.at_base = False

    def advance(self, x, s):
        """Move the cached iterate from the current Jacobian's g to the Newton iterate g - x (what the
        SNES's full step makes next), its pressure to p - (s - mean s).  ``s`` must be m x up to
        rounding (contactset.py: x = c s + a rigid shift); its mean is removed because m has no q = 0
        mode.  Nothing if the iterate already moved (keep, or a second call): the next ensure() then
        computes the pressure.  Collective (the mean)."""
        if not (self.valid and self.at_base):
            return
        self.pressure_after(s, self.p)
        self.g -= x
        self.at_base = False

    def smooth_step(self, g0, x, sweeps, ratio):
        """Replace the Newton step ``x`` from the iterate ``g0`` (arrays of the local rows; the next iterate
        is g0 - x) by g0 - S(max(g0 - x, 0)), S ``sweeps`` projected Richardson sweeps (warmstart.smooth_gap,
        Chebyshev nodes of [m_max / ``ratio``, m_max]; one FFT pair each).  The cached iterate's gap array
        is the sweeps' memory, so it is invalid afterwards (the next ensure() computes the pressure).
        Collective."""
        g = np.subtract(g0, x, out=self.g)
        np.maximum(g, 0.0, out=g)
        self.valid = self.at_base = False
        smooth_gap(self.op, g, sweeps, ratio, out=g)
        np.subtract(g0, g, out=x)

    def pressure_after(self, s, out):
        """``out`` = p - (s - mean s), the pressure of the iterate g - x when m x = s (``out`` may be
        self.p).  Collective (the mean)."""
        mean = self.fft.mean(s)
        np.subtract(self.p, s, out=out)
        out += mean
        return out

    def update_active_set(self):
        """C = {p^ >= kappa g^} of the current iterate (never empty: mean p^ = 1 > 0, so the most
        compressed point is taken if no point qualifies).  Returns how many points changed since the
        previous call, -1 on the first."""
        comm = self.comm
        act = self.p >= self.op.kappa_gap(self.g)
        nact = comm.allreduce(int(np.count_nonzero(act)), op=MPI.SUM)
        if nact == 0:
            val = self.p - self.kappa * self.g
            loc = float(val.max()) if val.size else -np.inf
            best = comm.allreduce((loc, comm.rank), op=MPI.MAXLOC)
            if comm.rank == best[1] and val.size:
                act.flat[int(np.argmax(val))] = True
            nact = 1
        change = -1 if self.updates == 0 else comm.allreduce(int(np.count_nonzero(act != self.act)), op=MPI.SUM)
        self.at_base = True
        self.act = act
        self.nact = nact
        self.updates += 1
        return change

    def contact_set(self):
        """{p^ >= kappa g^} of the cached iterate (local rows): the returned solution's contact set."""
        return self.p >= self.op.kappa_gap(self.g)

    def measures(self, act=None):
        """(complementarity, penetration, force) of the cached iterate (operator.py), all ranks; ``act``
        is its contact_set() if given."""
        return self.op.measures(self.g, self.p, self.contact_set() if act is None else act)
