"""The semismooth Newton step solved on the free set (for large contact sets).

Newton system of the gap formulation (snes.py), contact set C, free set F (nondimensional):

    J x = P_C x + P_F m x / kappa = r.

Its rows on C give x_C = r_C; the rows on F then leave a system for x_F alone,

    A x_F = b,    A = (m P_F . )_F / kappa,    b = r_F - (m P_C r_C)_F / kappa,

the stiffness of the free set (not symmetric for a viscoelastic modulus).  The inner KSP (default
GMRES, right preconditioning: its residual is the free-set residual of J x = r, in h_rms) solves it
with the fixed linear PC

    B z = kappa ((c P_F z)_F - <c P_F z>_C),

the compliance on F with a rigid shift (the correction does not move the contact set on average).
Cost per Newton step: 1 FFT pair + 2 per inner Krylov iteration (A and B).  The Krylov vectors have
|F| entries, and the C rows are solved exactly instead of being part of the Krylov problem: against
the same GMRES on whole-grid vectors (the method up to session 11, deleted) it takes fewer
iterations and less time at high speed (benchmarks/RESULTS.md, "Free-set steps replace whole-grid
steps"), and the restart that fits the memory budget grows by N^2 / |F|.  The inner KSP has the SNES's own options prefix
(``-ksp_type``, ``-ksp_gmres_restart``, ``-ksp_pc_side``, ...; the outer KSP is ``preonly``);
restart SolverSettings.restart of the first free set's size.

Long solves (fast sliding at large A/A0) switch to cycles (``start_cycles``, when StepPolicy.cycling
says so): FGMRES preconditioned by exactly SolverSettings.free_cycle iterations of unpreconditioned
GMRES on A (one FFT pair an iteration).  The outer basis stays short, which cuts the
orthogonalisation that makes up half of such a solve (benchmarks/RESULTS.md, "free_cycle").  The
cycles run with a float32 basis under PETSc's float64 FGMRES (subset.SingleCycles,
SolverSettings.cycle_precision single), or as PETSc's PCKSP (double; inner options ``-ksp_ksp_*``).
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI

from vecontact.solver.settings import PETSC_FREE_CYCLE_DEFAULTS, PETSC_FREE_DEFAULTS
from vecontact.solver.subset import Restricted, SingleCycles, SubsetStep, gather

__all__ = ["FreeSetStep"]


class FreeSetStep(SubsetStep):
    """Python PC of the outer (Newton) KSP: y = J^{-1} x up to the inner KSP's tolerance, solved on F.

    ``activate(ksp)``, ``set_active(act, n_active)``, ``set_tolerances``, ``iterations``, ``solves`` and
    ``release()`` as for ContactSetStep (contactset.py).
    """

    mode = "free"

    def __init__(self, op, kappa, PETSc, prefix, settings, work=None):
        super().__init__(op, kappa, PETSc, prefix, settings, work)
        self.act = None
        self.n_active = 0

    # ------------------------------------------------------------------ SubsetStep hooks
    def defaults(self, n_loc):
        restart = self.comm.allreduce(self.settings.restart(n_loc), op=MPI.MIN)
        return dict(PETSC_FREE_DEFAULTS, ksp_gmres_restart=str(restart))

    def start_cycles(self):
        """From the next solve on, FGMRES over cycles of free_cycle GMRES iterations (StepPolicy.cycling):
        a short outer basis, so little orthogonalisation an iteration; the cycles in float32
        (SingleCycles) or, cycle_precision double, in PETSc.  Nothing when free_cycle is 0,
        when it already runs so, or when the user chose the inner KSP's type (-ksp_type).  Collective."""
        k = self.settings.free_cycle
        if k == 0 or self.cycle > 1 or not self.own_krylov():
            return
        if self.settings.cycle_precision == "single":   # the cycles with a float32 basis (subset.py)
            restart = self.settings.single_restart(self.idx.size, "free", 2, reserve=k + 3)
            restart = self.comm.allreduce(restart, op=MPI.MIN)
            self.configure(dict(PETSC_FREE_DEFAULTS, ksp_type="fgmres", ksp_gmres_restart=str(restart)),
                           SingleCycles(self, k))
            return
        restart = self.settings.restart(self.idx.size, vectors=2, reserve=k + 1)
        restart = self.comm.allreduce(restart, op=MPI.MIN)
        self.configure(dict(PETSC_FREE_CYCLE_DEFAULTS, ksp_gmres_restart=str(restart), ksp_ksp_max_it=str(k),
                            ksp_ksp_gmres_restart=str(k)))

    def operator(self):
        return Restricted(self, self.op.m, scale=1.0 / self.kappa)      # m / kappa: the Jacobian's free rows

    def preconditioner(self):
        # kappa c: the compliance in units of the Jacobian's rows
        return Restricted(self, self.op.c, self._rigid_shift, scale=self.kappa)

    def _rigid_shift(self, z, full):
        # <kappa c P_F z>_C removed; the sum over C is the grid's minus F's (not where=act: RESULTS.md)
        f8 = np.float64                                   # float32 z, full: sums in float64 (single.py)
        z -= self.fft.sum(np.sum(full, dtype=f8) - np.sum(z, dtype=f8)) / self.n_active

    def set_active(self, act, n_active):
        """Contact set ``act`` (bool, local rows) with ``n_active`` points on all ranks (> 0)."""
        self.act = act
        self.n_active = int(n_active)
        n_F = self.fft.N * self.fft.N - self.n_active
        if n_F > 0:
            self.select(np.flatnonzero(~act.ravel()), n_F)
        else:
            self.n_S = 0

    # ------------------------------------------------------------------ PC interface
    def apply(self, pc, x, y):
        r = x.getArray(readonly=True).reshape(self.shape)
        xo = y.getArray().reshape(self.shape)
        np.copyto(xo, r)                                  # x_C = r_C
        if self.n_S == 0:                                 # full contact: J = identity
            return
        np.multiply(r, self.act, out=self.w)              # P_C r
        self.fft.apply(self.w, self.op.m, self.out, 1.0 / self.kappa)   # m P_C r / kappa
        b = self._b.getArray()
        gather(r, self.idx, b)
        b -= np.take(self.out.ravel(), self.idx)
        self._r = r
        self.solve()
        self.update(self._y, xo)

    def update(self, y, xo):
        """The whole-grid Newton update ``xo`` (local rows) of the inner solution ``y`` (a Vec on F) for
        the right-hand side of the running apply: x_C = r_C, x_F = y.  No FFT.  Returns None: the
        pressure increment m x is not known without a pair (contactset.py's returns it)."""
        np.copyto(xo, self._r)
        xo.reshape(-1)[self.idx] = y.getArray(readonly=True)
        return None
