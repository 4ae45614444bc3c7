"""Matrix-free PETSc SNES solve of the contact NCP in the gap formulation.

Unknown: the nondimensional gap g^ >= 0 (units h_rms), pressure p^(g^) = 1 + m (g^ + h^) (units sigma0).
m has no q = 0 mode, so mean(p^) = 1 for every iterate: load control for free, no extra unknown.
NCP:  g^ >= 0,  p^ >= 0,  g^ p^ = 0.

Default method: semismooth Newton (= primal-dual active set) on the min-residual
    F(g^) = min(g^, p^(g^) / kappa)           (kappa = k ell / sigma0, see operator.py)
with SNES newtonls + basic (full-step) line search.  Active (contact) set C = {p^ >= kappa g^} of the
current iterate, free set F its complement.  Generalised Jacobian (Python Mat, one FFT pair)
    J x = P_C x + P_F m x / kappa.
The Newton step J x = r is solved in one of two ways, chosen before every step from the size of the
current contact set (``contact_step auto``, the default; ``contact_step contact|free`` forces one;
``contact_step_area`` sets the switch, CONTACT_STEP_AREA = 0.3 up to 2048^2, 0.15 above):
* A/A0 <= 0.3: on the contact set (contactset.py).  KSP ``preonly`` with a Python PC that eliminates
  the free set exactly and runs an inner FGMRES (options prefix ``contact_``) on the restricted
  compliance c_CC, preconditioned by the restricted stiffness m_CC.  Its Krylov vectors live on C
  (A/A0 of the grid): orthogonalisation is cheap; 2 FFT pairs per inner iteration.
* A/A0 > 0.3: on the whole grid.  KSP GMRES (right preconditioning, restart RESTART_MAX = 120 capped
  by memory: 43 at 4096^2 on 2 ranks) with the Python PC "identity on C, Fourier-diagonal compliance
  on F plus a rigid shift" B r = P_C r + kappa P_F (c P_F r - <c P_F r>_C); 2 FFT pairs per iteration.
Measured (paper surfaces, HN compound, 1 rank): the contact-set step needs 20-45 % fewer FFT pairs
and 3-4x less time below A/A0 ~ 15 %.  From 15 to 30 % it needs about the same pairs in 1.3-2.3x less
time (no orthogonalisation over N^2 vectors; 1024^2 and 2048^2, v = 0.01-10 m/s).  Above, at
v = 10 m/s, its inexact steps (gap errors on C) make the active set wander: 2048^2, 43 %: 18 Newton
steps, 6384 pairs, 997 s against 14, 1756, 401 s on the grid (at 0.1 m/s, 64 % it still wins).
Linear tolerance (either way): loose (``lin_rtol``, default 0.1, at most LIN_MAXIT_CHANGING = 40
iterations) while the active set changes between Newton steps; tightened 10x (and the cap doubled)
whenever a step makes too little progress (``tighten_steps``: the set changes grow, or shrink by less
than 1 / WANDER_RATIO, or the residual does not fall); "exact" once the set stops changing (the step
is then the solution, PDAS converges in one more step), with the absolute tolerance tol/kappa
(free-set residual, h_rms units; the 2-norm bounds the max-norm measure) or INNER_ATOL_FACTOR tol/kappa
(gap error on C).
``-snes_ksp_ew``, ``-ksp_rtol``/``-ksp_atol`` or ``-contact_ksp_rtol``/``-contact_ksp_atol`` in
petsc_options switch this rule off.  ``-ksp_type`` (default gmres) applies to the grid steps.
Convergence is decided by our own scale-free test (operator.py), installed with
SNESSetConvergenceTest.

Alternatives selectable with ``petsc_options`` (measured: see benchmarks/solver.py and the README):
``-snes_type vinewtonrsls`` (PETSc reduced-space VI on the NCP written as bounds g^ >= 0 with residual
p^(g^); Jacobian m, createSubMatrix gives the free-set block, KSP FGMRES, the PC is the compliance on
the free set with the rigid shift): converges, ~1.3x the FFT pairs of the earlier default.
``-snes_type vinewtonssls`` (semismooth Fischer-Burmeister; Jacobian Db m + Da, transpose via conj(m)):
runs, but the compliance PC does not fit the scaled Jacobian; did not converge in 30 Newton steps at
256^2.  ``-contact_ksp_type gmres/bcgs/...`` change the inner solver.
"""
from __future__ import annotations

import gc
import time

import numpy as np
from mpi4py import MPI

from vecontact.solver.contactset import ContactSetStep

__all__ = ["ncp_solve", "petsc"]

_PETSC = None


def petsc():
    """Import petsc4py lazily (after mpi4py), initialising PETSc once."""
    global _PETSC
    if _PETSC is None:
        from petsc4py import PETSc
        _PETSC = PETSc
    return _PETSC


def _reason_name(PETSc, cls, value):
    for k in dir(cls):
        if not k.startswith("_") and getattr(cls, k) == value:
            return k
    return str(value)


class _State:
    """Residual, Jacobian and preconditioner of the semismooth formulation (all ranks)."""

    def __init__(self, op, tol, lin_rtol, vi=False):
        self.op = op
        fft = op.fft
        self.fft = fft
        self.shape = fft.local_real_shape
        self.kappa = op.kappa * AS_FACTOR   # PDAS parameter c (active set p >= c g)
        self.tol = tol
        self.lin_rtol = lin_rtol
        self.vi = vi
        self.g = fft.real_array()      # iterate of the cached pressure
        self.p = fft.real_array()      # p^(g) of the last residual evaluation
        self.valid = False
        self.tmp = fft.real_array()
        self.tmp2 = fft.real_array()
        self.act = np.zeros(self.shape, dtype=bool)
        self.m_k = op.m / self.kappa        # Jacobian multiplier on the free rows
        self.c_k = op.c * self.kappa        # free-set preconditioner multiplier
        self.freef = fft.real_array()       # 1.0 on F, 0.0 on C
        self.nact = 0
        self.mode = None                    # "contact" | "free": where the Newton step is solved
        self.act_prev = None
        self.nchg_history = []
        self.lin_history = []
        self.history = []
        self.n2 = float(op.N) ** 2
        self.step = None
        self.ksp = None
        self.maxit_changing = LIN_MAXIT_CHANGING

    # ------------------------------------------------------------------ helpers
    def _view(self, vec, readonly=True):
        return vec.getArray(readonly=readonly).reshape(self.shape)

    def ensure(self, g):
        """Make sure (self.g, self.p) is the iterate g (recompute p if not)."""
        if self.valid and np.array_equal(g, self.g):
            return
        np.copyto(self.g, g)
        self.op.pressure(self.g, self.p)
        self.valid = True

    def active_set(self):
        act = self.p >= self.kappa * self.g
        comm = self.fft.comm
        nact = comm.allreduce(int(np.count_nonzero(act)), op=MPI.SUM)
        if nact == 0:  # a contact set is needed (mean p = 1 > 0); take the most compressed point
            val = self.p - self.kappa * self.g
            loc = float(val.max()) if val.size else -np.inf
            best = comm.allreduce((loc, comm.rank), op=MPI.MAXLOC)
            if comm.rank == best[1] and val.size:
                act.flat[int(np.argmax(val))] = True
        return act

    # ------------------------------------------------------------------ SNES callbacks
    def residual(self, snes, X, F):
        g = self._view(X)
        self.ensure(g)
        f = self._view(F, readonly=False)
        if self.vi:
            np.copyto(f, self.p)
        else:
            np.minimum(self.g, self.p / self.kappa, out=f)

    def jacobian(self, snes, X, J, P):
        g = self._view(X)
        self.ensure(g)
        if self.vi:
            self.jac_ctx.Db = None
            self.jac_ctx.Da = None
            return
        act = self.active_set()
        comm = self.fft.comm
        if self.act_prev is None:
            nchg = -1
        else:
            nchg = comm.allreduce(int(np.count_nonzero(act != self.act_prev)), op=MPI.SUM)
        self.nchg_history.append(nchg)
        self.lin_history.append(self.linear_iterations(snes))
        self.act_prev = act
        self.act = act
        self.nact = comm.allreduce(int(np.count_nonzero(act)), op=MPI.SUM)
        mode = self.step_mode
        if mode == "auto":
            mode = "contact" if self.nact <= self.step_area * self.n2 else "free"
        if mode != self.mode:
            self._switch(mode)
        if mode == "contact":
            self.step.set_active(act)
        else:
            np.logical_not(act, out=self.freef, casting="unsafe")
        if self.lin_rtol is not None:
            if nchg == 0 and len(self.nchg_history) >= 2 and self.nchg_history[-2] == 0:
                # the previous step was already solved "exactly" on this active set and did not
                # converge: the 2-norm tolerance was too loose for the max-norm measure
                self.atol *= 0.03
            if tighten_steps(self.nchg_history, [r for _, r, _ in self.history]):
                self.lin_rtol = max(0.1 * self.lin_rtol, LIN_RTOL_MIN)
                self.maxit_changing = min(2 * self.maxit_changing, self.ksp_max_it)
            # both tolerances bound the max-norm measure (see ncp_solve)
            atol = self.atol * (INNER_ATOL_FACTOR if mode == "contact" else 1.0)
            # the first step of a (warm) start decides the active set the rest refines: solve it
            # 10x tighter (measured: 2048^2, v = 10 m/s, 4 %: half the FFT pairs)
            rtol = 1e-14 if nchg == 0 else (FIRST_RTOL_FACTOR * self.lin_rtol if nchg < 0 else self.lin_rtol)
            maxit = self.ksp_max_it if nchg == 0 else min(self.ksp_max_it, self.maxit_changing)
            if mode == "contact":
                self.step.set_tolerances(rtol, atol, maxit)
            else:
                self.ksp.setTolerances(rtol=rtol, atol=atol, max_it=maxit)

    def linear_iterations(self, snes):
        """Krylov iterations so far: outer GMRES (free-set steps) + inner (contact-set steps; the
        outer preonly KSP counts each of those solves as one iteration)."""
        return snes.getLinearSolveIterations() - self.step.solves + self.step.iterations

    def _switch(self, mode):
        """Solve the next Newton steps on the contact set (KSP preonly + ContactSetStep) or on the
        grid (KSP GMRES + _FreeSetPC)."""
        pc = self.ksp.getPC()
        if mode == "contact":
            self.ksp.setType("preonly")
            pc.setPythonContext(self.step)
        else:
            self.ksp.setType(self.free_ksp_type)
            if self.free_ksp_type in ("fgmres", "gmres"):
                self.ksp.setGMRESRestart(self.restart)
            if self.free_pc_side_right:
                # the PC is a fixed linear map: right-preconditioned GMRES = FGMRES with half the memory
                self.ksp.setPCSide(self._PETSc.PC.Side.RIGHT)
            pc.setPythonContext(self.free_pc)
        self.mode = mode
        self.modes.append((len(self.nchg_history) - 1, mode))

    def converged(self, snes, it, norms):
        PETSc = petsc()
        X = snes.getSolution()
        g = self._view(X)
        self.ensure(g)
        act = self.p >= self.op.kappa * self.g
        meas = self.op.measures(self.g, self.p, act)
        res = max(meas)
        self.last_measures = meas
        self.history.append((it, res, self.fft.transforms))
        if self.monitor is not None:
            self.monitor(it, res, meas)
        if res <= self.tol:
            return PETSc.SNES.ConvergedReason.CONVERGED_FNORM_ABS
        if not np.isfinite(res):
            return PETSc.SNES.ConvergedReason.DIVERGED_FNORM_NAN
        if it >= snes.getTolerances()[3]:
            return PETSc.SNES.ConvergedReason.DIVERGED_MAX_IT
        return PETSc.SNES.ConvergedReason.ITERATING


class _JacobianMat:
    """J x = P_C x + P_F m x / kappa (semismooth) or J x = Db (m x) + Da x (VI mode; Db, Da are the
    row scaling and diagonal shift vinewtonssls applies to the Jacobian, none for vinewtonrsls)."""

    def __init__(self, st):
        self.st = st
        self.Db = None
        self.Da = None

    def mult(self, mat, x, y):
        st = self.st
        xa = st._view(x)
        ya = st._view(y, readonly=False)
        if st.vi:
            st.fft.apply(xa, st.op.m, ya)
            if self.Db is not None:
                ya *= self.Db
            if self.Da is not None:
                ya += self.Da * xa
            return
        st.fft.apply(xa, st.m_k, ya)       # m x / kappa on every point
        np.copyto(ya, xa, where=st.act)    # identity rows on the contact set

    def multTranspose(self, mat, x, y):
        """VI mode only: J^T x = m^T (Db x) + Da x; the transpose of a real Fourier multiplier
        operator has the multiplier conj(m)."""
        st = self.st
        xa = st._view(x)
        ya = st._view(y, readonly=False)
        src = xa if self.Db is None else xa * self.Db
        if not hasattr(st, "m_conj"):
            st.m_conj = np.conj(st.op.m)
        st.fft.apply(np.ascontiguousarray(src), st.m_conj, ya)
        if self.Da is not None:
            ya += self.Da * xa

    def diagonalScale(self, mat, L=None, R=None):
        if R is not None and bool(R):
            raise NotImplementedError("right diagonal scaling")
        if L is not None and bool(L):
            d = L.getArray(readonly=True).reshape(self.st.shape).copy()
            self.Db = d if self.Db is None else self.Db * d
            if self.Da is not None:
                self.Da = self.Da * d

    def setDiagonal(self, mat, D, addv=None):
        d = D.getArray(readonly=True).reshape(self.st.shape).copy()
        self.Da = d if self.Da is None else self.Da + d

    def createSubMatrix(self, mat, isrow, iscol=None, cll=None, submat=None):
        """Square submatrix J_II on the index set I (for vinewtonrsls): scatter, J, gather."""
        idx = isrow.getIndices() - self.st.fft.row_start * self.st.fft.N
        n = idx.size
        ntot = self.st.fft.comm.allreduce(n, op=MPI.SUM)
        ctx = _SubMat(self, idx)
        if submat is not None and submat.getSize()[0] == ntot:
            submat.getPythonContext().__init__(self, idx)
            return submat
        sub = self.st._PETSc.Mat().createPython(((n, ntot), (n, ntot)), context=ctx, comm=self.st.fft.comm)
        sub.setUp()
        return sub


class _SubMat:
    def __init__(self, parent, idx):
        self.parent = parent
        self.idx = idx

    def mult(self, mat, x, y):
        st = self.parent.st
        full = st.tmp2
        full[...] = 0.0
        full.flat[self.idx] = x.getArray(readonly=True)
        st.fft.apply(full, st.op.m, st.tmp)
        out = st.tmp.flat[self.idx]
        if self.parent.Db is not None:
            out = out * self.parent.Db.flat[self.idx]
        if self.parent.Da is not None:
            out = out + self.parent.Da.flat[self.idx] * x.getArray(readonly=True)
        y.getArray()[:] = out


class _PythonPC:
    """Base of the Python PC contexts: they read the solver state ``st``."""

    def __init__(self, st):
        self.st = st

    def setUp(self, pc):
        pass


class _ViPrecond(_PythonPC):
    """Compliance PC of the VI modes: c r (vinewtonssls); on the reduced space of vinewtonrsls the
    compliance on the free index set I with a rigid shift (mean zero off I)."""

    def apply(self, pc, x, y):
        st = self.st
        A, _ = pc.getOperators()
        ctx = A.getPythonContext() if A.getType() == "python" else None
        if isinstance(ctx, _SubMat):
            idx = ctx.idx
            full = st.tmp2
            full[...] = 0.0
            full.flat[idx] = x.getArray(readonly=True)
            st.fft.apply(full, st.op.c, st.tmp)
            mask = np.ones(st.shape, dtype=bool)
            mask.flat[idx] = False
            buf = np.array([np.sum(st.tmp, where=mask), np.count_nonzero(mask)], dtype=float)
            st.fft.comm.Allreduce(MPI.IN_PLACE, buf, op=MPI.SUM)
            if buf[1] > 0:
                st.tmp -= buf[0] / buf[1]
            y.getArray()[:] = st.tmp.flat[idx]
            return
        st.fft.apply(st._view(x), st.op.c, st._view(y, readonly=False))


class _FreeSetPC(_PythonPC):
    """Newton step on the whole grid (outer GMRES), for large contact sets:
    B r = P_C r + kappa P_F (c P_F r - <c P_F r>_C), identity on C and the compliance on F with a rigid
    shift (the correction does not move the contact set on average)."""

    def apply(self, pc, x, y):
        st = self.st
        ra = st._view(x)
        ya = st._view(y, readonly=False)
        act = st.act
        np.multiply(ra, st.freef, out=st.tmp2)           # P_F r
        st.fft.apply(st.tmp2, st.c_k, ya)                # kappa c P_F r
        ya -= st.fft.sum(np.sum(ya, where=act)) / st.nact    # rigid shift: <.>_C = 0
        np.copyto(ya, ra, where=act)                     # identity on the contact set


# Global (unprefixed) defaults: PETSc's own 4-way unrolled VecMDot/VecMAXPY for the Krylov basis
# instead of BLAS dgemv.  With the reference BLAS PETSc links here dgemv re-reads x for every basis
# vector: measured (1 rank, v = 10 m/s) VecMDot 1.88 -> 1.14 s at 512^2 (20 %), 18.7 -> 10.8 s of a
# 50 s solve at 1024^2 (28 %).  A user's value (petsc_options or PETSC_OPTIONS) wins.
GLOBAL_DEFAULTS = {"vec_mdot_use_gemv": "0", "vec_maxpy_use_gemv": "0"}


def _apply_global_options(PETSc, user_items):
    """Set GLOBAL_DEFAULTS (or the user's value of those keys) without the solver prefix."""
    opts = PETSc.Options()
    for k, v in GLOBAL_DEFAULTS.items():
        if k in user_items:
            opts[k] = user_items[k]
        elif not opts.hasName(k):
            opts[k] = v


def _apply_options(PETSc, prefix, defaults, user):
    """Put defaults (unless given by the user) and the user options into the options database."""
    opts = PETSc.Options()
    keys = []
    user_items = [(k, v) for k, v in _parse_options(user) if k not in GLOBAL_DEFAULTS]
    user_keys = {k for k, _ in user_items}
    for k, v in defaults.items():
        if k not in user_keys:
            opts[prefix + k] = v
            keys.append(prefix + k)
    for k, v in user_items:
        opts[prefix + k] = v
        keys.append(prefix + k)
    return keys


def _parse_options(user):
    """dict {'snes_type': 'x'} / {'-snes_type': 'x'} or list of '-key value' strings -> [(key, value)]."""
    items = []
    if user is None:
        return items
    if isinstance(user, dict):
        for k, v in user.items():
            k = str(k).lstrip("-")
            if v is None or v is True:
                v = ""
            elif v is False:
                v = "false"
            items.append((k, str(v)))
        return items
    if isinstance(user, str):
        user = [user]
    toks = []
    for s in user:
        toks.extend(str(s).split())
    i = 0
    while i < len(toks):
        k = toks[i]
        if not k.startswith("-"):
            raise ValueError(f"petsc_options: expected '-key [value]', got {k!r}")
        v = ""
        if i + 1 < len(toks) and not (toks[i + 1].startswith("-") and not _is_number(toks[i + 1])):
            v = toks[i + 1]
            i += 1
        items.append((k.lstrip("-"), v))
        i += 1
    return items


def _is_number(s):
    try:
        float(s)
        return True
    except ValueError:
        return False


_COUNTER = [0]
AS_FACTOR = 1.0   # PDAS c = AS_FACTOR x kappa
# cap of the KSP iterations of Newton steps whose active set changed; measured (1024^2, v = 10 m/s,
# 28 %): 14 Newton steps at 20, 8 at 40 (active-set changes 4474, 2248, 1009, ... against 3705, 612, 221, ...)
LIN_MAXIT_CHANGING = 40


def default_restart(nloc, budget=None, vectors=1):
    """GMRES restart length: RESTART_MAX, capped so that its ``vectors`` x (restart + 1) basis vectors
    fit in RESTART_MEMORY bytes per rank (GMRES 1, FGMRES 2; 4096^2 on 2 ranks: 43 and 21)."""
    budget = RESTART_MEMORY if budget is None else budget
    return int(max(10, min(RESTART_MAX, budget // (8 * vectors * max(nloc, 1)) - 1)))


RESTART_MEMORY = 3e9
# measured (1024^2, v = 10 m/s, 28 %, final Newton step): 380 / 168 / 145 / 101 iterations at restart
# 20 / 45 / 60 / 100; benchmark, v = 10, 30 %, 2 ranks: restart 120 against 60 = 1048 against 1148 pairs
# and 23.6 against 23.4 s at 1024^2, 1497 against 1705 pairs and 160 against 169 s at 2048^2
RESTART_MAX = 120
LIN_RTOL_MIN = 1e-6
FIRST_RTOL_FACTOR = 0.1
# auto: contact-set steps while A/A0 <= this, grid steps above.  Measured 0.15 -> 0.3 (seconds, 1 rank,
# contact-set / grid steps): 2048^2, v = 10 m/s, 28 %: 243 / 374; 1024^2, 19-28 %: v = 1: 11.5 / 26.2,
# 18.6 / 26.6; v = 10: 17.8 / 33.0, 22.8 / 42.9.  2048^2, v = 10, 43 %: 997 / 401 (see the docstring)
# Not above 2048^2: at 4096^2 on 2 ranks, v = 1 m/s, 28 % a contact-set solve ran > 35 min where the
# grid-step solve of 0.1 m/s, 28 % took 13 min (not side by side; paper run, session 4).  Side by side
# with tighten_steps (2 ranks, idle): 1 m/s, 28 %: grid steps 954 s; contact-set steps stopped at 1047 s.
CONTACT_STEP_AREA = 0.3
CONTACT_STEP_AREA_LARGE = 0.15   # N > CONTACT_STEP_LARGE_N
CONTACT_STEP_LARGE_N = 2048
INNER_ATOL_FACTOR = 5.0   # measured: 0.5 costs ~5 % more pairs, 20 one more Newton step
# tighten_steps: set changes shrinking by less than 1 / WANDER_RATIO per step.  Measured (Newton steps /
# FFT pairs, without / with the rule): 4096^2, 2 ranks, 1 m/s, 28 %, grid steps: 15 / 2403 -> 7 / 2466
# (changes 69409, 29531, 11882, 4579, ... -> 69404, 29526, 11281, 1604, 42, 0); contact-set steps:
# 2048^2, 10 m/s, 43 %: 18 / 6384 -> 9 / 2217; 1024^2, 10 m/s, 28 %: 10 / 884 -> 6 / 856; grid steps,
# 1024^2, 43-64 %: 1-2 Newton steps fewer, pairs within 2 %
WANDER_RATIO = 0.3


def tighten_steps(changes, residuals):
    """True when the inexact Newton steps must be solved tighter (rtol 10x lower, iteration cap 2x).

    ``changes``: active-set changes per Newton step (-1 for the first); ``residuals``: the convergence
    measure per iterate.  Tighten when the set changes shrink by less than 1 / WANDER_RATIO per step
    (this includes growing: the steps' errors flip points, more so at large N and v), or when the
    residual did not fall (the first step often overshoots, hence from the third iterate on).
    """
    wandering = len(changes) >= 3 and changes[-2] > 0 and changes[-1] > WANDER_RATIO * changes[-2]
    stalled = len(residuals) >= 3 and residuals[-1] >= residuals[-2]
    return wandering or stalled


def default_step_area(N):
    """A/A0 up to which ``contact_step auto`` solves Newton steps on the contact set (N x N grid)."""
    return CONTACT_STEP_AREA if N <= CONTACT_STEP_LARGE_N else CONTACT_STEP_AREA_LARGE


def ncp_solve(op, g0, tol=1e-8, petsc_options=None, max_it=100, lin_rtol=0.1, restart=None,
              monitor=None, ksp_max_it=400):
    """Solve the NCP of ``op`` (ContactOperator) from the nondimensional gap ``g0``.

    Returns (ghat, phat, active, info); info has iterations, linear_iterations, converged, reason,
    residual, measures, history.
    """
    PETSc = petsc()
    fft = op.fft
    comm = fft.comm
    nloc = int(np.prod(fft.local_real_shape))
    ntot = fft.N * fft.N
    user_items = dict(_parse_options(petsc_options))
    snes_type = user_items.get("snes_type", "newtonls")
    vi = snes_type.startswith("vi")
    free_ksp_type = user_items.get("ksp_type", "fgmres" if vi else "gmres")
    if restart is None:
        restart = fft.comm.allreduce(default_restart(nloc, vectors=2 if free_ksp_type == "fgmres" else 1),
                                     op=MPI.MIN)
    _COUNTER[0] += 1
    prefix = f"vecontact{_COUNTER[0]}_"
    own_lin = not any(k in user_items for k in ("snes_ksp_ew", "ksp_rtol", "ksp_atol",
                                                 "contact_ksp_rtol", "contact_ksp_atol"))
    st = _State(op, tol, lin_rtol if own_lin else None, vi=vi)
    st.monitor = monitor
    st.ksp_max_it = int(user_items.get("contact_ksp_max_it", ksp_max_it))
    # inner residual = gap error on C (h_rms); the measure sees its image under m, |m rho| <= 2 kappa |rho|
    # 2-norm >= max-norm: a free-set step solved to tol/kappa meets the measure; a contact-set step's
    # residual is a gap error on C whose image under m is what the measure sees (INNER_ATOL_FACTOR)
    st.atol = tol / st.kappa
    st.restart = int(user_items.get("ksp_gmres_restart", restart))
    st.free_ksp_type = free_ksp_type
    st.free_pc_side_right = free_ksp_type == "gmres" and "ksp_pc_side" not in user_items
    st.step_mode = user_items.get("contact_step", "auto")
    if st.step_mode not in ("auto", "contact", "free"):
        raise ValueError(f"petsc option contact_step: expected auto, contact or free, got {st.step_mode!r}")
    st.step_area = float(user_items.get("contact_step_area", default_step_area(fft.N)))
    st.modes = []
    defaults = {
        "snes_type": "newtonls",
        "snes_linesearch_type": "basic",
        "ksp_gmres_restart": str(restart),
        "snes_max_linear_solve_fail": "1000",
    }
    if vi:
        defaults.update({"ksp_type": "fgmres", "ksp_gmres_restart": str(restart),
                         "ksp_max_it": str(ksp_max_it),
                         "snes_vi_zero_tolerance": "1e-12", "ksp_rtol": "1e-3",
                         "snes_linesearch_type": "bt" if snes_type == "vinewtonssls" else "basic"})
        st.atol = 0.0
    _apply_global_options(PETSc, user_items)
    keys = _apply_options(PETSc, prefix, defaults, petsc_options)
    snes = None
    try:
        X = PETSc.Vec().createMPI((nloc, ntot), comm=comm)
        X.getArray()[:] = np.asarray(g0, dtype=float).ravel()
        Fv = X.duplicate()
        st._PETSc = PETSc
        st.jac_ctx = _JacobianMat(st)
        J = PETSc.Mat().createPython(((nloc, ntot), (nloc, ntot)), context=st.jac_ctx, comm=comm)
        J.setUp()
        snes = PETSc.SNES().create(comm=comm)
        snes.setOptionsPrefix(prefix)
        snes.setFunction(st.residual, Fv)
        snes.setJacobian(st.jacobian, J, J)
        ksp = snes.getKSP()
        pc = ksp.getPC()
        pc.setType("python")
        if vi:
            pc.setPythonContext(_ViPrecond(st))
        else:
            st.step = ContactSetStep(op, st.kappa, PETSc, prefix)
            st.free_pc = _FreeSetPC(st)
            pc.setPythonContext(st.step)
        snes.setTolerances(max_it=int(max_it))
        snes.setConvergenceTest(st.converged)
        if vi:
            lo = X.duplicate()
            lo.set(0.0)
            hi = X.duplicate()
            hi.set(PETSc.INFINITY)
            snes.setVariableBounds(lo, hi)
        snes.setFromOptions()
        st.ksp = ksp
        t0 = time.perf_counter()
        snes.solve(None, X)
        reason_code = snes.getConvergedReason()
        reason = _reason_name(PETSc, PETSc.SNES.ConvergedReason, reason_code)
        its = snes.getIterationNumber()
        lits = snes.getLinearSolveIterations() if vi else st.linear_iterations(snes)
        g = X.getArray(readonly=True).reshape(fft.local_real_shape)
        st.ensure(g)
        act = st.p >= op.kappa * st.g
        meas = op.measures(st.g, st.p, act)
        res = max(meas)
        converged = bool(res <= tol)
        ghat = st.g.copy()
        phat = st.p.copy()
        info = dict(iterations=int(its), linear_iterations=int(lits), converged=converged,
                    reason="converged" if converged else reason.lower(), residual=float(res),
                    measures=meas, history=st.history, nchg=st.nchg_history,
                    lin_history=st.lin_history + [int(lits)], modes=st.modes,
                    seconds=time.perf_counter() - t0, snes_type=snes.getType(), ksp_type=ksp.getType())
        for obj in (X, Fv, J):
            obj.destroy()
        return ghat, phat, act, info
    finally:
        if st.step is not None:
            st.step.release()
        if snes is not None:
            snes.destroy()
        # Free the solve's N^2 arrays now.  The state and its PETSc contexts reference each other
        # (partly through C, invisible to the cyclic GC): drop the references and collect.  petsc4py
        # then only parks the collected objects of a multi-rank communicator (a collective destroy
        # from a finaliser could deadlock), and a parked PC keeps its Python context alive:
        # garbage_cleanup destroys them (without it, +0.9 GB per case and rank at 4096^2 on 2 ranks).
        st.step = st.jac_ctx = st.free_pc = st.ksp = None
        ksp = pc = None
        gc.collect()
        PETSc.garbage_cleanup(comm)
        opts = PETSc.Options()
        for k in keys:
            try:
                opts.delValue(k)
            except Exception:
                pass
