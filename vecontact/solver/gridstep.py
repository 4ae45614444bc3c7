"""The semismooth Newton step solved on the whole grid (for large contact sets).

Newton system of the gap formulation (snes.py), contact set C, free set F (nondimensional):

    J x = P_C x + P_F m x / kappa = r.

The outer KSP (default GMRES with right preconditioning: the PC below is a fixed linear map, so this is
FGMRES with half the basis memory) solves it with the Python PC

    B r = P_C r + kappa P_F (c P_F r - <c P_F r>_C),

identity on C and the compliance c = 1/m on F with a rigid shift (the correction does not move the
contact set on average).  2 FFT pairs per Krylov iteration (J and B).  The KSP is the SNES's own
(options prefix ``<solver prefix>``, i.e. ``-ksp_type``, ``-ksp_gmres_restart``, ``-ksp_pc_side``).
"""
from __future__ import annotations

import numpy as np

__all__ = ["GridStep"]


class GridStep:
    """Python PC of the outer KSP for grid steps, and the set-up of that KSP.

    ``activate(ksp)`` makes the next Newton steps grid steps; ``set_active(act, n_active)`` gives the
    contact set of the current Jacobian; ``set_tolerances`` the Krylov tolerances of its solve.
    """

    def __init__(self, op, kappa, PETSc, ksp_type, restart, pc_side_right):
        self.fft = op.fft
        self.PETSc = PETSc
        self.shape = op.fft.local_real_shape
        self.c_k = op.c * kappa              # kappa c: the compliance in units of the Jacobian's rows
        self.freef = self.fft.real_array()   # 1.0 on F, 0.0 on C
        self.tmp = self.fft.real_array()
        self.act = None
        self.n_active = 0
        self.ksp_type = ksp_type
        self.restart = restart
        self.pc_side_right = pc_side_right
        self.ksp = None

    def activate(self, ksp):
        """Solve the next Newton steps with ``ksp`` (the SNES's KSP) on the whole grid."""
        ksp.setType(self.ksp_type)
        if self.ksp_type in ("fgmres", "gmres"):
            ksp.setGMRESRestart(self.restart)
        if self.pc_side_right:
            ksp.setPCSide(self.PETSc.PC.Side.RIGHT)
        ksp.getPC().setPythonContext(self)
        self.ksp = ksp

    def set_active(self, act, n_active):
        """Contact set ``act`` (bool, local rows) with ``n_active`` points on all ranks (> 0)."""
        self.act = act
        self.n_active = n_active
        np.logical_not(act, out=self.freef, casting="unsafe")

    def set_tolerances(self, rtol, atol, max_it):
        self.ksp.setTolerances(rtol=rtol, atol=atol, max_it=max_it)

    # ------------------------------------------------------------------ PC interface
    def setUp(self, pc):
        pass

    def apply(self, pc, x, y):
        ra = x.getArray(readonly=True).reshape(self.shape)
        ya = y.getArray().reshape(self.shape)
        act = self.act
        np.multiply(ra, self.freef, out=self.tmp)                  # P_F r
        self.fft.apply(self.tmp, self.c_k, ya)                      # kappa c P_F r
        ya -= self.fft.sum(np.sum(ya, where=act)) / self.n_active   # rigid shift: <.>_C = 0
        np.copyto(ya, ra, where=act)                                # identity on the contact set

    def release(self):
        """Drop the references to PETSc objects (the KSP is the SNES's)."""
        self.ksp = None
