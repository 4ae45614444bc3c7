"""What the two Newton-step solvers share: an inner Krylov solve whose vectors live on a subset S of
the grid (the contact set C in contactset.py, the free set F in freeset.py).

Both are PETSc Python PCs of the outer (Newton) KSP, which is ``preonly``: the PC solves the Newton
system J x = r (snes.py) by eliminating the complement of S exactly and running an inner KSP on S.
Orthogonalisation, the memory-bound part of a Krylov iteration, then costs |S| instead of N^2 per
basis vector, and the GMRES restart that fits the memory budget grows by N^2 / |S|.
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI

__all__ = ["Restricted", "SubsetStep"]


class Restricted:
    """y = (multiplier P_S x)_S, then ``post(y, full)`` with ``full`` the whole-grid product (Python Mat
    and Python PC of the inner KSP).  ``multiplier``: a Fourier multiplier of the SlabFFT."""

    def __init__(self, step, multiplier, post=None):
        self.step = step
        self.multiplier = multiplier
        self.post = post

    def _apply(self, x, y):
        s = self.step
        s.buf.reshape(-1)[s.idx] = x.getArray(readonly=True)   # not .flat[idx] nor np.put: slower (RESULTS.md)
        s.fft.apply(s.buf, self.multiplier, s.out)
        ya = y.getArray()
        np.take(s.out.ravel(), s.idx, out=ya)
        if self.post is not None:
            self.post(ya, s.out)

    def mult(self, mat, x, y):
        self._apply(x, y)

    def apply(self, pc, x, y):
        self._apply(x, y)

    def setUp(self, pc):
        pass


class SubsetStep:
    """Base of the Newton-step PCs: the inner KSP on the points ``idx`` of S, its restricted operator,
    the option defaults it puts into PETSc's database (removed again by ``release``) and the count of
    its iterations.

    A subclass gives ``defaults(n_loc)`` (option defaults under ``inner_prefix``, from the local size
    of the first S), ``operator()`` and ``preconditioner()`` (Restricted contexts) and ``apply``; it
    calls ``select(idx, n_S)`` from its ``set_active`` and ``solve()`` from its ``apply``.
    """

    def __init__(self, op, kappa, PETSc, inner_prefix, settings):
        self.op = op
        self.fft = fft = op.fft
        self.comm = fft.comm
        self.kappa = float(kappa)
        self.PETSc = PETSc
        self.settings = settings
        self.shape = fft.local_real_shape
        self.buf = fft.real_array()     # zero outside S (maintained by select)
        self.out = fft.real_array()
        self.w = fft.real_array()
        self.idx = np.zeros(0, dtype=np.intp)
        self._r = None                  # right-hand side (local rows) of the running apply, for update()
        self.n_S = 0
        self.iterations = 0             # inner Krylov iterations of the ``solves`` applies
        self.cycle = 1                  # Krylov iterations per iteration of self.ksp (nested: the inner's)
        self.solves = 0
        self._A = self._b = self._y = None
        self.ksp = PETSc.KSP().create(comm=self.comm)
        self._prefix = inner_prefix
        self.ksp.setOptionsPrefix(inner_prefix)
        self._configured = False
        self._own_keys = []

    def activate(self, ksp):
        """Solve the next Newton steps with the outer ``ksp`` as preonly + this PC."""
        ksp.setType("preonly")
        ksp.getPC().setType("python")     # a -pc_type under the shared prefix is the inner KSP's, not this one's
        ksp.getPC().setPythonContext(self)

    def set_tolerances(self, rtol, atol, max_it):
        """``max_it`` counts Krylov iterations; nested (``cycle`` > 1), whole cycles of the outer KSP."""
        self.ksp.setTolerances(rtol=rtol, atol=atol, max_it=-(-max_it // self.cycle))

    def setUp(self, pc):
        pass

    def select(self, idx, n_S):
        """Make S the local points ``idx`` (flat, sorted), ``n_S`` points on all ranks (> 0)."""
        PETSc = self.PETSc
        self.buf.reshape(-1)[self.idx] = 0.0
        n_loc = int(idx.size)
        self.idx = idx
        self.n_S = int(n_S)
        resize = self._A is None or self._A.getLocalSize()[0] != n_loc
        if self.comm.size > 1:   # collective: every rank must take the same branch
            resize = self.comm.allreduce(resize, op=MPI.LOR)
        if resize:
            if self._A is not None:
                self.ksp.reset()          # a KSP cannot change its operator's size otherwise
                for obj in (self._A, self._b, self._y):
                    obj.destroy()
            self._A = PETSc.Mat().createPython(((n_loc, self.n_S), (n_loc, self.n_S)),
                                               context=self.operator(), comm=self.comm)
            self._A.setUp()
            self._b = self._A.createVecLeft()
            self._y = self._A.createVecRight()
        self.ksp.setOperators(self._A)
        if not self._configured:
            self.configure(self.defaults(n_loc))
            self._configured = True

    def configure(self, defaults):
        """Put ``defaults`` into the options database under the inner prefix (where the user has not set
        the key; this step's own earlier defaults are replaced), then set the inner KSP from it.  A
        ``-pc_type ksp`` there nests it (free_cycle): the Python PC goes to the inner KSP of PCKSP, and
        ``cycle`` becomes that KSP's iteration count, which it always runs in full."""
        opts = self.PETSc.Options()
        for k, v in defaults.items():
            key = self._prefix + k
            if key in self._own_keys or not opts.hasName(key):
                opts[key] = v
                if key not in self._own_keys:
                    self._own_keys.append(key)
        pc = self.ksp.getPC()
        pc.setType("python")
        pc.setPythonContext(self.preconditioner())
        self.ksp.setFromOptions()
        self.cycle = 1
        if pc.getType() == "ksp":
            inner = pc.getKSP()
            inner.getPC().setType("python")
            inner.getPC().setPythonContext(self.preconditioner())
            inner.setFromOptions()
            self.cycle = inner.getTolerances()[3]

    def solve(self):
        """Inner solve of A y = b (the vectors ``_b``, ``_y``) from y = 0."""
        self._y.set(0.0)
        self.ksp.solve(self._b, self._y)
        self.iterations += self.cycle * self.ksp.getIterationNumber()
        self.solves += 1

    def release(self):
        """Destroy the inner KSP and its operators; remove the option defaults this step put in."""
        for obj in (self._A, self._b, self._y, self.ksp):
            if obj is not None:
                obj.destroy()
        self._A = self._b = self._y = self.ksp = None
        opts = self.PETSc.Options()
        for k in self._own_keys:
            try:
                opts.delValue(k)
            except Exception:
                pass
        self._own_keys = []
