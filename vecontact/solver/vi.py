"""``-snes_type vinewtonrsls``: PETSc's reduced-space VI Newton method, the alternative to the default.

The NCP is handed to PETSc as bounds g^ >= 0 with the residual p^(g^) = 1 + m (g^ + h^) (nondimensional,
operator.py).  The Jacobian is m (a Python Mat, one FFT pair per product); PETSc solves each Newton step
on the inactive (free) index set I through ``createSubMatrix``, with KSP FGMRES and the Python PC
"compliance on I with a rigid shift" (mean zero off I).  Slower than the default semismooth method
(about 1.3x its FFT pairs, benchmarks/RESULTS.md) and kept as an independent second solver of the same
problem; option defaults in settings.PETSC_VI_DEFAULTS.  With the bt line search it is also a
fallback of a solve whose full steps cannot converge (-vc_fallback vi: snes.ncp_solve).  The
semismooth VI variant (vinewtonssls) was removed: it did not converge with this preconditioner.
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI

from vecontact.solver.subset import Grid, gather

__all__ = ["ViNewton"]


class ViNewton:
    """SNES callbacks, Jacobian (Python Mat context) and set-up of the VI formulation on ``state``
    (a NewtonState)."""

    def __init__(self, state, PETSc):
        self.state = state
        self.PETSc = PETSc
        self.grid = Grid(state.fft)          # scatter / gather buffers of the sub-matrix products

    def configure(self, snes, X):
        """Python PC and the bounds 0 <= g^ < inf."""
        snes.getKSP().getPC().setPythonContext(_ViPrecond(self))
        lo = X.duplicate()
        lo.set(0.0)
        hi = X.duplicate()
        hi.set(self.PETSc.INFINITY)
        snes.setVariableBounds(lo, hi)

    def linear_iterations(self, snes):
        return snes.getLinearSolveIterations()

    def diagnostics(self, linear_iterations):
        """No active set of ours and one kind of step: nothing but the linear iterations."""
        return dict(nchg=[], lin_history=[linear_iterations], modes=[])

    def release(self):
        pass

    # ------------------------------------------------------------------ SNES callbacks
    def residual(self, snes, X, F):
        st = self.state
        st.ensure(st.view(X))
        np.copyto(st.view(F, readonly=False), st.p)

    def jacobian(self, snes, X, J, P):
        self.state.ensure(self.state.view(X))

    # ------------------------------------------------------------------ Mat context: J = m
    def mult(self, mat, x, y):
        st = self.state
        st.fft.apply(st.view(x), st.op.m, st.view(y, readonly=False))

    def createSubMatrix(self, mat, isrow, iscol=None, cll=None, submat=None):
        """Square submatrix J_II on the index set I: scatter, J, gather."""
        fft = self.state.fft
        idx = isrow.getIndices() - fft.row_start * fft.N
        ntot = fft.comm.allreduce(idx.size, op=MPI.SUM)
        if submat is not None and submat.getSize()[0] == ntot:
            submat.getPythonContext().idx = idx
            return submat
        sub = self.PETSc.Mat().createPython(((idx.size, ntot), (idx.size, ntot)), context=_SubMat(self, idx),
                                            comm=fft.comm)
        sub.setUp()
        return sub

    def on_index_set(self, idx, x, multiplier, y, shift_off=False):
        """y = (multiplier x~)_I with x~ = x on I, 0 elsewhere; ``shift_off``: minus the mean off I first."""
        st = self.state
        g = self.grid
        g.product_of(idx, x.getArray(readonly=True), multiplier, 1.0)
        ya = y.getArray()
        gather(g.out, idx, ya)
        if shift_off:   # sum and count off I: the grid's minus I's (not a masked sum: RESULTS.md)
            buf = np.array([np.sum(g.out) - np.sum(ya), g.out.size - idx.size], dtype=float)
            st.fft.comm.Allreduce(MPI.IN_PLACE, buf, op=MPI.SUM)
            if buf[1] > 0:
                ya -= buf[0] / buf[1]


class _SubMat:
    """J_II = (m .)_I on the inactive index set ``idx`` (local flat indices)."""

    def __init__(self, vi, idx):
        self.vi = vi
        self.idx = idx

    def mult(self, mat, x, y):
        self.vi.on_index_set(self.idx, x, self.vi.state.op.m, y)


class _ViPrecond:
    """The compliance on the inactive set I with a rigid shift (mean zero off I); c r on the whole grid
    when PETSc hands over the full Jacobian (no bound active)."""

    def __init__(self, vi):
        self.vi = vi

    def setUp(self, pc):
        pass

    def apply(self, pc, x, y):
        vi = self.vi
        st = vi.state
        A, _ = pc.getOperators()
        ctx = A.getPythonContext() if A.getType() == "python" else None
        if isinstance(ctx, _SubMat):
            vi.on_index_set(ctx.idx, x, st.op.c, y, shift_off=True)
        else:
            st.fft.apply(st.view(x), st.op.c, st.view(y, readonly=False))
