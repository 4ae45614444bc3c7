"""``-snes_type vinewtonrsls``: PETSc's reduced-space VI Newton method, the alternative to the default.

The NCP is handed to PETSc as bounds g^ >= 0 with the residual p^(g^) = 1 + m (g^ + h^) (nondimensional,
operator.py).  The Jacobian is m (a Python Mat, one FFT pair per product); PETSc solves each Newton step
m_II y = r on the inactive (free) index set I through ``createSubMatrix``, the gap held on the active
set A (the rest).  That is the Newton system of the default method's contact-set step (contactset.py)
on A, so the Python PC solves it there: KSP ``preonly``, the PC's inner FGMRES on A (options prefix
``contact_``) to ksp_max_it and an rtol (ViNewton.iterate): with the bt line search, the iterate's
convergence measure within [vi_step_rtol, vi_step_rtol_max] (1e-5, 1e-2), and vi_step_rtol after a
loose step that bt cut; without it, vi_step_rtol.  No edge term: with it the steps of the sharp and
SLS rubbers stalled.  The FGMRES keeps a float32 basis (single.py) where its pairs are float32 too
(SubsetStep.float32_pairs_hold) and SolverSettings.step_precision of 1 / rtol allows it: its
orthogonalisation, not its pairs, was half of a long step's time in float64 [RESULTS.md].  A step
after one that used all of ksp_max_it restarts every vi_capped_restart iterations instead of
inner_restart_max: restarted FGMRES had stagnated in such steps one after the other [RESULTS.md].
A loose step leaves a gap error on A whose pressure on I (m_IA) can make the step no descent for the
line search (RESULTS.md, "the VI method's steps on the contact set" and "`vi_step_rtol_max`").  With A
empty the PC is the compliance c (m's inverse on the whole grid).  A user's ``-ksp_type`` (say
``fgmres``) runs on I with this PC.  As a whole solve (with bt) it takes about
2x the default's FFT pairs on the paper's rubber but 0.04-0.73x them where the default's full steps
fail (RESULTS.md); it is kept as an independent second solver of the same problem; option defaults
in settings.PETSC_VI_DEFAULTS.  With the bt line search it is also the fallback of a solve whose full
steps cannot converge, and of the grids finer than one whose full steps failed (-vc_fallback vi,
-vc_fallback_coarse: snes.ncp_solve, contact.py).  The semismooth VI variant (vinewtonssls) was
removed: it did not converge with the compliance preconditioner.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from mpi4py import MPI

from vecontact.solver.subset import counters, gather

__all__ = ["ViNewton"]


class ViNewton:
    """SNES callbacks, Jacobian (Python Mat context) and set-up of the VI formulation on ``state``
    (a NewtonState)."""

    def __init__(self, state, PETSc, step):
        self.state = state
        self.PETSc = PETSc
        self.step = step                     # ContactSetStep: m_II^-1 through the active set
        self.grid = step.grid                # the sub-matrix products' buffers: the step's (subset.Workspace)
        self._idx = None                     # the inactive set the step was last set to
        self._vecs = None                    # whole-grid right-hand side and update of the step
        self.rtol = step.settings.vi_step_rtol   # the next step's Krylov rtol (iterate)
        self._evals = 0                      # residual evaluations since the last iterate
        self._loose = False                  # the last step was solved looser than vi_step_rtol
        self._settings = step.settings
        self._capped = False                 # the last step used all of ksp_max_it (a longer restart next)
        self.petsc_restart = None            # the restart set on the step's PETSc FGMRES (_petsc_restart)

    def configure(self, snes, X):
        """Python PC and the bounds 0 <= g^ < inf."""
        snes.getKSP().getPC().setPythonContext(_ViPrecond(self))
        lo = X.duplicate()
        lo.set(0.0)
        hi = X.duplicate()
        hi.set(self.PETSc.INFINITY)
        snes.setVariableBounds(lo, hi)

    def iterate(self, snes, measure):
        """A new iterate, of convergence ``measure`` (snes._Convergence): the next step's rtol.  With the
        bt line search it is SolverSettings.vi_rtol(measure), loose far from the solution and
        tightening as the iterates converge, unless bt cut the last step (more than one residual
        evaluation) after a loose solve: then vi_step_rtol.  A loose step bt cuts points the wrong
        way, and such steps in a row crawled: the broad rubber at 512^2 took 51 iterations against
        5 (RESULTS.md, "`vi_step_rtol_max`").  Without a line search that judges the steps (PETSc's
        basic, the user's VI method's default), vi_step_rtol."""
        s = self.step.settings
        cut = self._loose and self._evals > 1
        judged = snes.getLineSearch().getType() == "bt"
        self.rtol = s.vi_rtol(measure) if judged and not cut else s.vi_step_rtol
        self._evals = 0

    def linear_iterations(self, snes):
        """The step's Krylov iterations, and the outer KSP's unless it is ``preonly`` (one a step)."""
        outer = 0 if snes.getKSP().getType() == "preonly" else snes.getLinearSolveIterations()
        return outer + self.step.iterations

    def diagnostics(self, linear_iterations):
        """No active set of ours and one kind of step: the linear iterations and the step's counts."""
        return dict(nchg=[], lin_history=[linear_iterations], modes=[], **counters([self.step]))

    def release(self):
        self.step.release()
        for v in self._vecs or ():
            v.destroy()
        self._vecs = self.step = None

    def stiffness_inverse(self, idx, x, y):
        """y = (m_II)^-1 x on the inactive set I (local flat ``idx``), the gap held on A (the rest): the
        contact-set step (contactset.py) of the Newton system x_A = 0, (m x)_I = kappa r_I with
        r_I = x / kappa, to ``rtol`` (``iterate``) and ksp_max_it.  False (nothing done) when A is
        empty on every rank.  Collective."""
        fft = self.state.fft
        self._loose = False
        act = np.ones(fft.local_real_shape, dtype=bool)
        act.reshape(-1)[idx] = False
        n_act = fft.comm.allreduce(int(np.count_nonzero(act)), op=MPI.SUM)
        if n_act == 0:
            return False
        if self._vecs is None:
            nloc = int(np.prod(fft.local_real_shape))
            r = self.PETSc.Vec().createMPI((nloc, fft.N * fft.N), comm=fft.comm)
            self._vecs = (r, r.duplicate())
        r, out = self._vecs
        step = self.step
        changed = self._idx is None or not np.array_equal(self._idx, idx)
        if fft.comm.allreduce(changed, op=MPI.LOR):       # set_active is collective
            step.set_active(act, n_act)
            self._idx = idx.copy()
        # restarted FGMRES can stagnate on these sets: after a step that ran out of iterations, the next
        # one keeps a longer basis (single.py reads it from the settings, PETSc's KSP is told); never a
        # shorter one than the others', and with vi_capped_restart 0 the settings as they are
        st = self._settings
        longer = self._capped and st.vi_capped_restart > 0
        step.settings = st
        if longer:                                        # act: every local point
            restart = st.vi_restart(fft.N, act.size, step.idx.size)
            step.settings = replace(st, inner_restart_max=max(st.inner_restart_max, restart))
        # a float32 basis only with float32 pairs: with float64 ones (the sharp rubber at 2048^2) its
        # tight steps took 2-3x the iterations [RESULTS.md]
        single = step.float32_pairs_hold() and st.step_precision(1.0 / self.rtol)[0]
        step.set_tolerances(self.rtol, 0.0, st.ksp_max_it, single=single)
        if not step.single:
            self._petsc_restart(step, longer)
        self._loose = self.rtol > st.vi_step_rtol
        ra = r.getArray()
        ra[:] = 0.0
        ra[idx] = x.getArray(readonly=True) / self.state.kappa
        its = step.iterations
        step.apply(None, r, out)
        self._capped = step.iterations - its >= st.ksp_max_it
        gather(out.getArray(readonly=True), idx, y.getArray())
        return True

    def _petsc_restart(self, step, longer):
        """The restart of the step's PETSc FGMRES: the one configured (inner_restart_max's) or, for a
        ``longer`` one after a step that ran out, the step's settings' (SolverSettings.vi_restart;
        ``petsc_restart``: the one set last, None before any); the user's -contact_ksp_gmres_restart
        always.  Set only when it changes (PETSc frees the basis then)."""
        if not step.own_option("ksp_gmres_restart"):
            return
        configured = self.PETSc.Options().getInt(step.ksp.getOptionsPrefix() + "ksp_gmres_restart")
        restart = (step.comm.allreduce(step.settings.inner_restart(step.idx.size), op=MPI.MIN) if longer
                   else configured)
        if restart != (self.petsc_restart or configured):
            step.ksp.setGMRESRestart(restart)
            self.petsc_restart = restart

    # ------------------------------------------------------------------ SNES callbacks
    def residual(self, snes, X, F):
        self._evals += 1
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
    """m_II^-1 through the contact-set step (ViNewton.stiffness_inverse); the compliance on I with a
    rigid shift (mean zero off I) where no point is active; c r on the whole grid when PETSc hands over
    the full Jacobian (no bound active)."""

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
            if not vi.stiffness_inverse(ctx.idx, x, y):
                vi.on_index_set(ctx.idx, x, st.op.c, y, shift_off=True)
        else:
            st.fft.apply(st.view(x), st.op.c, st.view(y, readonly=False))
