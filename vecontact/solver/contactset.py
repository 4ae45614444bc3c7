"""The semismooth Newton step, solved on the contact set (a PETSc Python PC with an inner KSP).

Newton system of the gap formulation (snes.py) for the contact set C (free set F):

    x_C = r_C,        (m x)_F = kappa r_F          (nondimensional: gap in h_rms, pressure in sigma0)

Writing s = m x (the pressure increment: zero mean, known on F: s_F = kappa r_F) and x = c s + e (c = 1/m,
e the rigid shift, m and c have no q = 0 mode) turns it into a problem for s_C only:

    (c s)_C + e = r_C,        sum_C s_C = -sum_F s_F.

With s_C = s0 + y (s0 uniform, carrying the sum) and P the removal of the mean over C, y solves

    A y = b,    A = P c_CC P,    b = P (r_C - (c s~)_C),   s~ = s_F on F, s0 on C,

an operator on the zero-sum vectors of C: the restricted compliance (single-layer operator of the
contact set), positive definite in the elastic case, non-symmetric but coercive for a viscoelastic
modulus.  It is preconditioned by the restricted stiffness B = P m_CC P (the opposite-order, "Calderon"
preconditioner: m and c are exact inverses on the full grid, the restriction only perturbs it near the
contact edges, so the iteration count grows only mildly with N).  At the edges B gets a local
correction, a sparse term from small dense solves on windows (edge.py; their half width
SolverSettings.edge_half_width, by the set's size and the modulus's and the stiffness's ranges, 0:
none; their rows SolverSettings.edge_rows, by the modulus's range).  The Krylov vectors live on C: at
A/A0 = 5 % they are 20x shorter than the grid, so orthogonalisation costs little next to the FFTs.

A changing step's inner solve starts from the last step's directions, their products mapped to the new
set with c's kernel columns of the points that changed (recycle.py, SolverSettings.carry_map_cost;
GCRO in single.py).  An exact step, whose set is the last step's, needs no map: its FGMRES starts from
the last step's directions and their products, known without an FFT pair (carry.py,
SolverSettings.carry_directions).  Neither while C has more than carry_area_max of the grid's points
(``carries``).

Cost per Newton step: 2 FFT pairs + 2 per inner Krylov iteration (A and B), one more where carried
directions are mapped, and one pair per grid and solve for each of the edge correction's and the map's
kernels.  The pressure of the next iterate needs no pair: m x = s is
known (NewtonState.advance).
The inner KSP has the options prefix ``<solver prefix>contact_`` (default FGMRES, right preconditioning,
so its residual norm is the gap error on C in units of h_rms; restart SolverSettings.inner_restart).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from mpi4py import MPI

from vecontact.solver.edge import EdgeCorrection
from vecontact.solver.measurestop import MeasureStop
from vecontact.solver.newton import NewtonState
from vecontact.solver.recycle import CarriedSpace, ComplianceKernel
from vecontact.solver.settings import PETSC_INNER_DEFAULTS
from vecontact.solver.subset import Restricted, SubsetStep, gather

__all__ = ["ContactSetStep", "oracle_solve"]


class ContactSetStep(SubsetStep):
    """Python PC of the outer (Newton) KSP: y = J^{-1} x exactly, up to the inner KSP's tolerance.

    ``activate(ksp)`` makes the next Newton steps contact-set steps (the outer KSP becomes ``preonly``);
    ``set_active(act, n_active)`` must give the contact set of the current Jacobian before ``apply``.
    ``iterations`` accumulates the inner Krylov iterations of the ``solves`` applies.  ``release()``
    destroys the inner KSP and its operators and removes the option defaults it put in.
    """

    mode = "contact"

    def __init__(self, op, kappa, PETSc, prefix, settings, work=None):
        super().__init__(op, kappa, PETSc, prefix + "contact_", settings, work)
        self.free = np.zeros(self.shape, dtype=bool)   # the free set F
        self.edge = None        # the edge term (EdgeCorrection) of the current set's half width, or None
        self.advance = None     # called (x, s) after each Newton update: NewtonState.advance (snes.py)
        self._kernel = None     # c(x) on every rank, for the map of carried directions (made on first use)

    # ------------------------------------------------------------------ SubsetStep hooks
    def defaults(self, n_loc):
        restart = self.comm.allreduce(self.settings.inner_restart(n_loc), op=MPI.MIN)
        return dict(PETSC_INNER_DEFAULTS, ksp_gmres_restart=str(restart))

    def operator(self):
        return Restricted(self, self.op.c, self._remove_mean)

    def preconditioner(self):
        return Restricted(self, self.op.m, self._remove_mean, local=self._edge_term)

    def _edge_term(self, x, y):
        """y += the current set's edge term of x (set_active picks its width); nothing without one."""
        if self.edge is not None:
            self.edge.add_to(x, y)

    def step_pc(self):
        """B, with float32 pairs where the inner KSP is vecontact's FGMRES and float32_pc() holds: a
        flexible method's preconditioner may round more than its operator (RESULTS.md, pc_range_max)."""
        B = self.preconditioner()
        flexible = self.PETSc.Options().getString(self._prefix + "ksp_type") == "fgmres"
        if self.own_krylov() and flexible and self.float32_pc():
            return B.on(self.float32_grid())
        return B

    def _remove_mean(self, y, full):
        self.removed = self.mean_C(y)
        y -= self.removed

    def maps_from(self, old):
        """Whether to map the directions of the last set ``old``: not when the map would cost more than
        carry_map_cost x N^2 in its measure, |C| (changed + 2 K): the kernel values it gathers, and per
        point of C its copies and the basis's products, about K^2 |C| flops; one unit of N^2 is about
        one FFT pair [RESULTS.md]; nor when the map's kernel (N^2 float32 on every rank,
        ComplianceKernel) would not fit within half of carry_memory.  Collective."""
        st = self.settings
        if not ComplianceKernel.fits(self.fft.N, st):
            return False
        changed = CarriedSpace.changed(self.fft, old, self.idx)
        return float(self.n_S) * (changed + 2 * st.carry_directions) <= st.carry_map_cost * float(self.fft.N) ** 2

    def map_space(self, space):
        """The last step's directions mapped to the current set (recycle.py).  Collective."""
        if self._kernel is None:
            self._kernel = ComplianceKernel(self.op)
        g = self.grid
        g.product_of(self.idx, np.ones(self.idx.size), self.op.c, 1.0)       # c 1_C: one pair
        ones_product = gather(g.out, self.idx, np.empty(self.idx.size))
        return space.mapped(self.fft, self.idx, self.n_S, self._kernel, ones_product)

    def carries(self):
        """... and the contact set has at most carry_area_max of the grid's points (n_S is global: the
        same on every rank) and the modulus's range on this grid is at least carry_modulus_min: the
        carry's passes over K vectors of the set grow with it, and saved more than they cost only in the
        long steps of fast sliding [RESULTS.md]."""
        st = self.settings
        return (super().carries() and self.n_S <= st.carry_area_max * float(self.fft.N) ** 2
                and self.op.modulus_range() >= st.carry_modulus_min)

    def release(self):
        super().release()
        self.edge = self.advance = self._kernel = None

    # ------------------------------------------------------------------ helpers
    def mean_C(self, a):
        """Mean over the (global) contact set of the C-vector ``a``."""
        return self.fft.sum(a) / self.n_S

    def set_active(self, act, n_active):
        """New contact set ``act`` (bool, local rows) with ``n_active`` points on all ranks (> 0)."""
        if int(n_active) == 0:
            raise ValueError("empty contact set")
        np.logical_not(act, out=self.free)
        self.select(np.flatnonzero(act.ravel()), n_active)
        st = self.settings
        modulus_range = self.op.modulus_range()
        w = st.edge_half_width(modulus_range, float(n_active) / float(self.fft.N) ** 2, self.op.stiffness_range(),
                               self.fft.N)
        rows = st.edge_rows(modulus_range)
        if w == 0:
            self.edge = None
        elif self.edge is None or self.edge.w != w or self.edge.rows != rows:
            # one term at a time (its arrays scale with the set); a new width costs one pair
            self.edge = EdgeCorrection(self.op, w, st.edge_drop, st.store_headroom, rows)
        if self.edge is not None:
            self.edge.build(act, self.idx)

    # ------------------------------------------------------------------ PC interface
    def apply(self, pc, x, y):
        fft = self.fft
        idx = self.idx
        r = x.getArray(readonly=True).reshape(self.shape)
        xo = y.getArray().reshape(self.shape)
        w = self.w
        np.multiply(r, self.free, out=w)
        w *= self.kappa                                   # s_F = kappa r_F, 0 on C
        s0 = -self.fft.sum(w) / self.n_S
        w.reshape(-1)[idx] = s0                           # s~
        fft.apply(w, self.op.c, self.out)                 # c s~
        b = self._b.getArray()
        gather(r, idx, b)
        b -= np.take(self.out.ravel(), idx)
        b -= self.mean_C(b)
        self._r = r
        self.solve()
        s = self.update(self._y, xo)
        if self.advance is not None:
            self.advance(xo, s)

    def update(self, y, xo):
        """The whole-grid Newton update ``xo`` (local rows) of the inner solution ``y`` (a Vec on C) for
        the right-hand side of the running apply (one FFT pair): x = c s + e, s = s~ + y on C.  Returns
        s = m x, the pressure increment (a work array, valid until the next update)."""
        idx = self.idx
        s = self.work.s                                   # the pressure increment
        np.copyto(s, self.w)
        s.reshape(-1)[idx] += y.getArray(readonly=True)
        self.fft.apply(s, self.op.c, xo)                  # c s
        # rigid shift; x = c s + e on C too, so that m x = s exactly: the inner residual stays a
        # small gap error on C instead of turning into pressures (m rho) on F that upset the set
        e = self.mean_C(np.take(self._r.ravel(), idx) - np.take(xo.ravel(), idx))
        xo += e
        return s


class _GMRESStep(ContactSetStep):
    """A contact-set step whose inner KSP defaults to right-preconditioned GMRES (oracle_solve's
    ``krylov="gmres"``; the user's -<prefix>contact_ksp_* options still win, and release() removes these
    defaults with the others)."""

    def defaults(self, n_loc):
        return dict(super().defaults(n_loc), ksp_type="gmres", ksp_pc_side="right")


def oracle_solve(op, act, rtol, max_it, settings, prefix="oracle_", *, memory, krylov="fgmres", tol=None):
    """The "oracle solve" of issue #15: one Newton step on the final contact set ``act`` (bool, local
    rows), from the uniform pressure p^ = 1 (g^ = -h^), its inner FGMRES run to ``rtol`` (atol 0, at
    most ``max_it`` iterations).  The Newton loop's FFT pairs are judged against its pairs.  The FGMRES
    does not restart (a restart adds iterations, and so would flatter the loop's ratio to it) unless its
    basis, two float64 vectors an iteration over the set, would pass ``memory`` bytes a rank: then it
    restarts where it fits (``restart``; iterations beyond it make the ratio a lower bound).

    ``krylov="gmres"``: right-preconditioned GMRES instead.  Its preconditioner m_CC is a fixed float64
    map, so its iterates are FGMRES's (the same iterations and residuals, benchmarks/RESULTS.md, "The
    oracle as right-preconditioned GMRES"), from one basis vector an iteration: twice the iterations fit
    ``memory``; it applies m_CC once more to form the solution (one pair more, and one at each restart).

    ``tol``: also the oracle at the solver's accuracy.  From p^ = 1 the measure starts at 6e2-8e4, and
    rtol 1e-8 leaves an iterate whose measure is 4e-5-5e-4, where the solver's answer meets tol (1e-8
    by default); run on, the float64 solve stalls near 1e-7 (1024^2, 10 m/s, 27 %) [RESULTS.md].  So a
    refinement follows: one more step on the same set from that iterate (its residual: one FFT pair),
    stopped at the first iterate that meets the solver's own test at ``tol`` (measurestop.MeasureStop,
    looking at every iteration once within 10x of it) or at ``max_it``.  The looks' FFT pairs are not
    counted (the solver's steps pay for theirs, so the ratio to this errs against the solver).

    Returns dict(iterations, pairs (FFT pairs of the grid of ``op``, set-up included), residual (the
    inner solve's final residual norm, h_rms), converged, restart); with ``tol`` also matched: dict(
    plain_measure: of the first solve's iterate, iterations and pairs of both solves, measure of the last
    iterate looked at, converged: it met tol, look_pairs, looks: MeasureStop.trace)."""
    from vecontact.solver.snes import hold_comm, petsc
    PETSc = petsc()
    fft = op.fft
    comm = fft.comm
    hold_comm(comm)
    nloc = int(np.prod(fft.local_real_shape))
    n_act = comm.allreduce(int(np.count_nonzero(act)), op=MPI.SUM)
    steps = {"fgmres": ContactSetStep, "gmres": _GMRESStep}
    if krylov not in steps:
        raise ValueError(f"oracle_solve: krylov {krylov!r} is not fgmres or gmres")
    # #15's step: m_CC alone (no edge term), float64; its restart from ``memory`` alone (the settings'
    # rule counts two vectors an iteration, GMRES keeps one)
    step = steps[krylov](op, op.kappa, PETSc, prefix,
                         replace(settings, pc_range_max=0.0, edge_window=0, inner_restart_max=max(1, int(max_it)),
                                 inner_restart_memory=float(memory) * (2 if krylov == "gmres" else 1)))
    r = y = stop = None
    try:
        t0 = fft.transforms
        step.set_active(act, n_act)
        # the restart the KSP was set from (the step's default from ``memory``, or the user's)
        restart = PETSc.Options().getInt(step.ksp.getOptionsPrefix() + "ksp_gmres_restart")
        step.set_tolerances(rtol, 0.0, max_it)
        def residual(g, p):
            """F(g) of a step on the set: g on C, p^/kappa on F (the next iterate g - x, as the SNES's)."""
            return np.where(act, g, p / op.kappa).ravel()

        # from g0 = -h^, where p^(g0) = 1
        r = PETSc.Vec().createMPI((nloc, fft.N * fft.N), comm=comm)
        r.getArray()[:] = residual(-op.hhat, 1.0)
        y = r.duplicate()
        step.apply(None, r, y)
        pairs = (fft.transforms - t0) / 2.0
        out = dict(iterations=int(step.iterations), pairs=float(pairs),
                   residual=float(step.ksp.getResidualNorm()), converged=bool(step.ksp.getConvergedReason() > 0),
                   restart=restart)
        if tol is not None:
            state = NewtonState(op)
            state.ensure(-op.hhat - y.getArray(readonly=True).reshape(fft.local_real_shape))
            stop = MeasureStop(state, tol, PETSc, margin=10.0)
            stop.attach(step)
            plain = max(op.measures(state.g, state.p, act))
            stop.arm(plain)
            r.getArray()[:] = residual(state.g, state.p)     # the refinement's, from the first solve's iterate
            step.set_tolerances(0.0, 0.0, max_it)
            step.apply(None, r, y)
            measure = stop.trace[-1][2] if stop.trace else None
            out["matched"] = dict(plain_measure=plain, iterations=int(step.iterations),
                                  pairs=float((fft.transforms - t0) / 2.0 - stop.pairs), measure=measure,
                                  converged=measure is not None and measure <= tol, look_pairs=stop.pairs,
                                  looks=list(stop.trace))
        return out
    finally:
        if stop is not None:
            stop.release()
        step.release()
        for v in (r, y):
            if v is not None:
                v.destroy()
