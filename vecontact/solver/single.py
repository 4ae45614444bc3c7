"""Restarted GMRES with a single-precision Krylov basis, for the Newton steps whose active set still
changes, and (flexible) for the exact ones.

A changing step only needs its Krylov residual cut by lin_rtol (policy.py), far above float32
rounding (6e-8); free-set steps tightened below SolverSettings.single_rtol_min (1e-2) run in double,
where a float32 basis left the next iterate less accurate (the contact set's flexible steps form
their solution from the preconditioned vectors and keep the float32 basis: single_rtol_min_contact).
An exact step runs here, flexible on either set, while it must cut its residual by at most
single_exact_reduction_max (1e5, a hundredth of float32's 1/eps); the measure stop (measurestop.py)
watches it through ``solve``'s monitor, whose trial solutions are the ones the solve would return.
The step's two costs are memory-bound: the classical Gram-Schmidt over the basis, and the FFT pairs
of the operator and of the preconditioner.  The basis is a float32 block streamed by BLAS sgemv: half
the bytes (its products summed in float64 over chunks, _dots).  The pairs can run in float32 too
(SlabFFT.single(), about half the time) only while the stiffness's range of scales is small: a
float32 pair rounds the preconditioned vector (a gap, dominated by long waves) to 6e-8 of its size,
and the stiffness then amplifies that noise at short waves by up to max|m_q| / min|m_q|
(SolverSettings.single_range_max); beyond it the pairs stay float64.
PETSc cannot do either: its vectors have one precision per build.

The method is PETSc's KSPGMRES (or, ``flexible``, KSPFGMRES) with right preconditioning, x0 = 0,
classical Gram-Schmidt without refinement, and its default test (||r|| <= max(rtol ||b||, atol), at
least ``min_it`` iterations), so the steps stop where PETSc's did.  The small Hessenberg problem and
every global sum are float64 (the sums bitwise identical on all ranks, SlabFFT._allsum).  At a restart
the residual is recomputed from the float64 right-hand side, and a cycle whose estimate stalls deep
in its solve restarts early (``solve``'s ``stall``: the float32 basis has lost its orthogonality and
the estimate no longer follows the true residual).  The solution is accumulated in float64.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["SingleGMRES", "dots", "project_out"]

# entries summed in float32 before the partial sums go on in float64 (_dots)
_CHUNK = 8192
# entries of a vector orthogonalised at a time (_subtract; a multiple of _CHUNK, so that its norm sums
# as _dots does): the fastest of 2^15-2^19 in RESULTS.md, "The Gram-Schmidt update in blocks"
_BLOCK = 32 * _CHUNK
# a basis row is rescaled by a power of two when its length leaves [2^-_RANGE, 2^_RANGE] (solve): far
# inside float32's range for the products of _dots; the rows grow by ~2^4.5 an iteration at 10 m/s, so
# about one iteration in ten rescales there (RESULTS.md, "An unnormalised float32 basis")
_RANGE = 32


def dots(M, v):
    """M @ v (float32), summed in float32 over chunks of _CHUNK entries and in float64 over the chunks
    (the local part: the caller sums over ranks).  One long float32 sum (BLAS sgemv) errs by ~sqrt(n) x
    6e-8: enough, at n ~ 1e6, to spoil the orthogonality of the basis and the steps (RESULTS.md)."""
    n = v.size
    c = n // _CHUNK
    out = np.zeros(M.shape[0])
    if c:
        Mc = M[:, :c * _CHUNK].reshape(M.shape[0], c, _CHUNK).transpose(1, 0, 2)
        vc = v[:c * _CHUNK].reshape(c, _CHUNK, 1)
        out += np.matmul(Mc, vc)[:, :, 0].sum(axis=0, dtype=np.float64)
    if n > c * _CHUNK:
        out += M[:, c * _CHUNK:] @ v[c * _CHUNK:]
    return out


def project_out(C, r, allsum):
    """r -= C^T (C r) for orthonormal float32 rows C and a float64 r (in place; the coefficients in the
    float32 rounding of r, their sums in float64 over chunks and ranks); returns the coefficients."""
    cr = allsum(dots(C, r.astype(np.float32)))
    r -= cr.astype(np.float32) @ C
    return cr


class SingleGMRES:
    """GMRES(restart) with a float32 Krylov basis on vectors of ``n_loc`` local entries.

    ``allsum(values)``: the global sum of a float64 array, identical on all ranks.  ``solve`` takes the
    operator and the preconditioner as callables ``A(z, out)`` and ``B(v, out)``: v (a basis vector)
    and ``out`` of A are float32, z and ``out`` of B are of ``work`` dtype (float64 keeps the
    preconditioned vectors, whose range of scales float32 cannot hold at large N and v, exact).
    ``flexible``: keep the preconditioned vectors B v_k (FGMRES's memory), so that the solution needs
    no further preconditioner apply (one FFT pair a solve less, as PETSc's FGMRES against its GMRES).
    ``basis`` and ``work``: memory to work in (float32 and ``work`` dtype, of ``sizes()`` entries),
    e.g. kept between solves.
    """

    def __init__(self, n_loc, restart, allsum, flexible=False, work=np.float32, basis_store=None,
                 work_store=None):
        self.n_loc = n = int(n_loc)
        self.restart = m = int(restart)
        self.allsum = allsum
        self.flexible = bool(flexible)
        nb, nw = self.sizes(n, m, flexible)
        basis_store = np.empty(nb, dtype=np.float32) if basis_store is None else basis_store
        work_store = np.empty(nw, dtype=work) if work_store is None else work_store
        self.V = basis_store[:(m + 1) * n].reshape(m + 1, n)
        self.u = basis_store[(m + 1) * n:(m + 1) * n + min(n, _BLOCK)]
        self.z = work_store[:n]
        self.Z = work_store[n:(m + 1) * n].reshape(m, n) if flexible else None
        self.rescales = 0     # basis rows rescaled by a power of two (solve), over all solves
        self.stalls = 0       # cycles restarted on a stalled estimate (solve's ``stall``), over all solves
        self.history = []     # residual estimates of the last solve, one per iteration (and ||b|| first)
        self.arnoldi = None   # (k, G) of the last cycle: A Z[j] = sum_i G[i, j] V[i] (+ C E; flexible; carry.py)
        self.projected = None  # E (carried x k) of the last cycle: C^T A Z[j] (GCRO, solve's ``carried``)

    @staticmethod
    def sizes(n_loc, restart, flexible):
        """Entries of the float32 basis memory (the basis, whose last row takes the operator's
        product, and _subtract's block) and of the work memory."""
        n = int(n_loc)
        return (restart + 1) * n + min(n, _BLOCK), (restart + 1 if flexible else 1) * n

    _dots = staticmethod(dots)

    def _subtract(self, M, h, t):
        """t -= h @ M (float32), a block of _BLOCK entries at a time, and returns the local t.t after it
        (summed as _dots): t is read and written once, where a whole-vector product, subtraction and
        norm make three passes over it and two over the product."""
        n = t.size
        u = self.u
        total = 0.0
        for s in range(0, n, _BLOCK):
            e = min(s + _BLOCK, n)
            ub, tb = u[:e - s], t[s:e]
            np.matmul(h, M[:, s:e], out=ub)
            tb -= ub
            total += float(self._dots(tb.reshape(1, -1), tb)[0])
        return total

    def _norm(self, v):
        return math.sqrt(float(self.allsum(self._dots(v.reshape(1, -1), v))[0]))

    def _project(self, carried, r, x):
        """x += U C^T r, r -= C C^T r (GCRO's start on the carried space; r float64)."""
        cr = project_out(carried.C, r, self.allsum)
        x += cr.astype(x.dtype) @ carried.U
        return r

    @staticmethod
    def _coefficients(k, H, g, s):
        """y of the update x += Z y (H_k y = g_k, upper triangular after the rotations), for the
        unnormalised rows (scales s)."""
        y = np.zeros(k)
        for i in range(k - 1, -1, -1):
            y[i] = (g[i] - H[i, i + 1:k] @ y[i + 1:]) / H[i, i]
        return y / s[:k]

    @staticmethod
    def _subtract_carried(x, y, E, carried):
        """x -= U E_k y (GCRO's carried part of the update; nothing without carried directions)."""
        if E is not None:
            x -= (E[:, :y.size] @ y).astype(x.dtype) @ carried.U

    def _add_flexible(self, x, y):
        """x += Z_k y (FGMRES's update); self.z is its scratch."""
        z = self.z
        np.dot(y.astype(z.dtype), self.Z[:y.size], out=z)
        x += z

    def _stalled(self, stall, start, k, beta):
        """Whether the running cycle (its first estimate history[start], its start residual ``beta``,
        k iterations in) stalls by ``stall`` = (reduction, window), or None: never (see ``solve``)."""
        if stall is None or k <= stall[1]:
            return False
        res = self.history[-1]
        return res <= stall[0] * beta and self.history[start + k - stall[1]] < 2.0 * res

    def _trial(self, out, x, k, H, g, s, E, carried):
        """``out`` = the solution after the first k iterations of the running cycle (monitor's build),
        formed as the solve forms its own."""
        np.copyto(out, x, casting="same_kind")
        y = self._coefficients(k, H, g, s)
        self._subtract_carried(out, y, E, carried)
        self._add_flexible(out, y)

    def solve(self, A, B, b, x, rtol, atol, max_it, min_it=1, carried=None, monitor=None, stall=None):
        """Solve A B u = b, x = B u (right preconditioning) from x = 0.  ``b``: right-hand side
        (n_loc); ``x``: output (n_loc, of the work dtype or float64).  Returns (iterations, residual
        estimate).  ``B`` None: no preconditioner (the basis vector itself goes to A, not a copy).

        ``carried``: GCRO (recycle.py), an object with rows ``U`` (work dtype) and ``C`` = A U (float32,
        orthonormal).  The solve starts from x = U C^T b, every product is kept orthogonal to C (its
        coefficients E), and the update is x += Z y - U E y; the residual estimate stays exact.

        ``monitor(its, res, build)`` (``flexible`` only), called at the start (its 0, build None) and
        after every iteration that did not end the solve: True ends it there.  ``build(out)`` writes the
        solution of the iterations so far into the float64 array ``out``, bit for bit what the solve
        returns if it ends there (the measure stop, measurestop.py).  Collective: ``res`` is the same on
        every rank, so must the answer be.

        ``stall``: (reduction, window) or None.  A cycle whose residual estimate is below ``reduction``
        times its start and fell by less than half over the last ``window`` iterations restarts (from
        the float64 residual of b): that deep, a float32 basis has lost its orthogonality and the
        estimate crawls while the true residual stands still [RESULTS.md].

        The basis is kept unnormalised: row i holds s_i v_i, v_i the orthonormal Arnoldi vector and
        s_i = |row i| (float64, s_0 = 1), so the operator's product, written into the next row, is
        orthogonalised in place and never divided by its norm (a pass over the vector saved; the
        scales enter the few Gram-Schmidt coefficients, H and y instead).  A row whose scale leaves
        [2^-_RANGE, 2^_RANGE] is multiplied by a power of two, which rounds nothing."""
        if monitor is not None and not (self.flexible and B is not None):
            raise ValueError("SingleGMRES.solve: a monitor needs the flexible method (its trial solution)")
        V, z = self.V, self.z
        x[...] = 0.0
        r = b
        its = 0
        bnorm = math.sqrt(float(self.allsum([float(np.dot(b, b))])[0]))
        self.history = [bnorm]
        target = max(rtol * bnorm, atol)
        res = bnorm
        self.projected = None
        if bnorm == 0.0:
            return 0, 0.0
        if carried is not None and carried.size:
            r = self._project(carried, np.array(b, dtype=np.float64), x)
            res = self._norm(r)
            if res == 0.0 or (res <= target and min_it <= 0):
                self.history.append(res)
                return 0, res
        else:
            carried = None
        if monitor is not None:
            monitor(0, res, None)                          # the start (no solution to build yet)
        while True:
            beta = self._norm(r) if its else res
            np.multiply(r, 1.0 / beta, out=V[0], casting="same_kind")
            m = self.restart
            H = np.zeros((m + 1, m))
            Hraw = np.zeros((m + 1, m)) if self.flexible else None   # H before the rotations
            E = np.zeros((carried.size, m)) if carried is not None else None
            cs, sn = np.zeros(m), np.zeros(m)
            g = np.zeros(m + 1)
            g[0] = beta
            s = np.ones(m + 1)
            start = len(self.history) - 1              # the cycle's first estimate in history
            k = 0
            while k < m:
                if B is None:
                    zk = V[k]
                else:
                    zk = self.Z[k] if self.flexible else z
                    B(V[k], zk)
                t = V[k + 1]
                A(zk, t)                                   # s_k A B v_k
                if E is not None:                          # ... less its part in span C
                    E[:, k] = self.allsum(self._dots(carried.C, t))
                    self._subtract(carried.C, E[:, k].astype(np.float32), t)
                dv = self.allsum(self._dots(V[:k + 1], t))  # classical Gram-Schmidt, sums in float64
                si = s[:k + 1]                             # the lengths s_i of rows 0..k
                tn = math.sqrt(float(self.allsum([self._subtract(V[:k + 1], (dv / si**2).astype(np.float32), t)])[0]))
                hn = tn / s[k]
                H[:k + 1, k] = dv / (si * s[k])
                H[k + 1, k] = hn
                if Hraw is not None:
                    Hraw[:k + 2, k] = H[:k + 2, k]
                for i in range(k):                         # earlier Givens rotations
                    a0, a1 = H[i, k], H[i + 1, k]
                    H[i, k], H[i + 1, k] = cs[i] * a0 + sn[i] * a1, -sn[i] * a0 + cs[i] * a1
                d = math.hypot(H[k, k], H[k + 1, k])
                cs[k], sn[k] = (H[k, k] / d, H[k + 1, k] / d) if d > 0 else (1.0, 0.0)
                H[k, k], H[k + 1, k] = d, 0.0
                g[k + 1] = -sn[k] * g[k]
                g[k] = cs[k] * g[k]
                res = abs(g[k + 1])
                k += 1
                its += 1
                self.history.append(res)
                s[k] = tn
                done = its >= max_it or (its >= min_it and res <= target) or hn == 0.0
                if not done and monitor is not None:
                    done = bool(monitor(its, res, lambda out, k=k: self._trial(out, x, k, H, g, s, E, carried)))
                stalled = not done and self._stalled(stall, start, k, beta)
                if done or stalled:
                    self.stalls += stalled
                    break
                e = math.frexp(tn)[1]
                if abs(e) > _RANGE:
                    t *= np.float32(math.ldexp(1.0, -e))
                    s[k] = math.ldexp(tn, -e)
                    self.rescales += 1
            # x += B (V_k y),  H_k y = g_k (upper triangular after the rotations); row k is free
            y = self._coefficients(k, H, g, s)
            self._subtract_carried(x, y, E, carried)
            if E is not None:
                self.projected = E[:, :k]
            if self.flexible and B is not None:
                self._add_flexible(x, y)
                # row i of V is s_i v_i, Z[j] = s_j B v_j and A B v_j = sum_i Hraw[i, j] v_i
                # (a happy breakdown leaves row k zero: s_k = 0, and its G row stays 0)
                ratio = np.divide(s[:k], s[:k + 1, None], out=np.zeros((k + 1, k)), where=s[:k + 1, None] > 0)
                self.arnoldi = (k, Hraw[:k + 1, :k] * ratio)
            else:
                t = V[k]
                np.dot(y.astype(np.float32), V[:k], out=t)
                if B is None:
                    x += t
                else:
                    B(t, z)
                    x += z
            if done:
                return its, res
            # restart: the residual of the float64 right-hand side
            np.copyto(z, x, casting="same_kind")
            A(z, V[0])
            r = b - V[0]
            if carried is not None:
                r = self._project(carried, r, x)
