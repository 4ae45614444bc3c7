"""Stop an exact Newton step's inner Krylov solve as soon as its update meets the SNES's own test.

Once the active set stopped changing, the step's update is the solution (policy.py).  Its Krylov
tolerance, atol = tol / kappa on the 2-norm of the step's residual, bounds the max-norm convergence
measure (operator.py) from above, often by far: the solve would run on after its update already
converged.  This KSP convergence test, run after PETSc's default one (or a float32-basis solve's
monitor, single.py, on the same terms), builds the update of the
current Krylov iterate from time to time, evaluates the measure of the next Newton iterate g - x
(one FFT pair, plus what building the update costs; on the contact set the update's pair gives the
pressure too) and stops the solve when it is <= tol.  The next
iterate is then kept, so the SNES's residual evaluation of it costs nothing.

When to look: with the set unchanged, the measure of the next iterate is about kappa ||r||_inf of the
step's residual r, and the KSP reports ||r||_2; their ratio rho drifts slowly (benchmarks/RESULTS.md,
"`measure_stop`").  The solve looks when rho x kappa ||r||_2 predicts a measure <= tol,
rho from the latest look, or before the first one from the current iterate's measure and the step's
initial residual.  A look that fails (the set changed, or rho grew) only moves the next one later.
"""
from __future__ import annotations

import numpy as np

__all__ = ["MeasureStop"]


class MeasureStop:
    """KSP convergence test of exact Newton steps (``attach`` it to each step's inner KSP once; ``arm`` it
    before an exact step, ``disarm`` it before the others).  ``trace``: (Krylov iterations of the step
    so far, counted as subset.py does, ||r||_2, measure of the trial iterate) of every look.  A look
    costs one FFT pair: the trial's pressure on the free set (freeset.py), the update on the contact
    set, whose pressure increment is then known (contactset.py ``update``); building the Krylov solution
    may cost one more (GMRES's right preconditioner); ``pairs``: the FFT pairs the looks took.

    ``margin``: look once the prediction is within this factor of tol (1: the solver's; above 1 the
    looks come every iteration near the end, so the solve stops at the first iterate that meets the
    test, not at the first look that does: contactset.oracle_solve's ``tol``)."""

    def __init__(self, state, tol, PETSc, margin=1.0):
        self.state = state
        self.tol = float(tol)
        self.margin = float(margin)
        self.pairs = 0.0
        self.CONVERGED = PETSc.KSP.ConvergedReason.CONVERGED_USER
        self.ITERATING = PETSc.KSP.ConvergedReason.ITERATING
        self.armed = False
        self.trace = []
        self._g = self._p = self._y = None     # trial iterate g - x, its pressure; the inner solution
        self._of = None                        # the step Vec self._y was duplicated from
        self._measure = None                   # the current iterate's measure (arm)
        self._rho = None

    def attach(self, step):
        """Add the test to ``step``'s inner KSP, after PETSc's default one, and to its float32-basis
        solves (``monitor``; once per step)."""
        step.ksp.addConvergenceTest(self, args=(step,))
        step.stop = self

    def arm(self, measure):
        """Watch the next step's solve; ``measure``: the convergence measure of the current iterate."""
        self.armed = True
        self._measure = float(measure)
        self._rho = None

    def disarm(self):
        self.armed = False

    def __call__(self, ksp, its, rnorm, step):
        return self.CONVERGED if self.look(its, rnorm, step, ksp.buildSolution) else self.ITERATING

    def monitor(self, step):
        """The test as a SingleGMRES monitor (single.py) of ``step``'s float32-basis solve, or None when
        not armed."""
        if not self.armed:
            return None
        return lambda its, res, build: self.look(its, res, step, build and (lambda y: build(y.getArray())))

    def look(self, its, rnorm, step, build):
        """True when the Krylov iterate of ``its`` iterations (residual 2-norm ``rnorm``) is a Newton
        iterate that meets the test (then kept); ``build(y)`` writes the inner solution into the Vec y."""
        if not self.armed:
            return False
        scale = self.state.kappa * rnorm
        if its == 0:
            self._rho = self._measure / scale if scale > 0 else None
            return False
        if self._rho is None or self._rho * scale > self.margin * self.tol:
            return False
        st = self.state
        t0 = st.fft.transforms
        if self._g is None:
            self._g = st.fft.real_array()
            self._p = st.fft.real_array()
        if self._of is not step._y:            # the step's vectors were remade (collectively: subset.py)
            if self._y is not None:
                self._y.destroy()
            self._y = step._y.duplicate()
            self._of = step._y
        build(self._y)
        ds = step.update(self._y, self._g)     # x, then g - x in place
        np.subtract(st.g, self._g, out=self._g)
        if ds is None:
            st.op.pressure(self._g, self._p)
        else:                                  # m x = ds known (contactset.py)
            st.pressure_after(ds, self._p)
        meas = max(st.op.measures(self._g, self._p))
        self.trace.append((step.krylov_iterations(its), float(rnorm), float(meas)))
        self._rho = meas / scale if scale > 0 else None
        self.pairs += (st.fft.transforms - t0) / 2.0
        if meas <= self.tol:
            st.keep(self._g, self._p)
            return True
        return False

    def release(self):
        if self._y is not None:
            self._y.destroy()
        self._y = self._g = self._p = self._of = None
