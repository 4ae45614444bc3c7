"""Krylov directions carried across the contact-set Newton steps whose set changed (GCRO).

A changing contact-set step solves A y = b, A = P c_CC P (contactset.py), on a set C that differs from
the last step's C' in a few points: L left it, J joined it.  The last step's directions u' (its
preconditioned vectors z, and those it carried itself) still span the slow modes of the new operator,
if their products are known on the new set without an FFT pair each.  c's kernel decays only as 1/r,
so no window holds it: each point that changed gets its kernel column over the whole set
(``ComplianceKernel``: c(x) on the whole grid, on every rank).  With the raw products w' = (c u')_C'
(before P):

    u = u' on C and C' (0 on J), less its mean mu over C
    (c u)(x) = w'(x) - sum_{l in L} c(x - l) u'(l)            x in C and C'
    (c u)(x) = sum_{y in C and C'} c(x - y) u'(y)             x in J
    less mu (c 1_C)(x)                                        (one FFT pair a step)

That is |C| (|L| + |J|) kernel values gathered and two matrix products of K columns, and the copies of
the K directions and products over C.  The map is made only when |C| (|L| + |J| + 2 K) <=
SolverSettings.carry_map_cost x N^2 (contactset.ContactSetStep.maps_from); after larger changes, and
on large contact sets, the step starts afresh.  The step's SingleGMRES then runs GCRO (single.py, ``carried``) on the orthonormalised
products (``CarriedSpace.basis``).  Its own directions (the last cycle's z, their products from the
Arnoldi relation), then the carried ones, K in all (carry_directions), are what the next step gets;
an exact step (unchanged set) starts PETSc's FGMRES from them (carry.py).

Products are float32 (the Krylov basis's precision), so the carried products err by ~1e-7 of their
size; they only shape a step's Krylov space, never the answer: the Newton residual that judges a step
is formed in float64.  Measurements: benchmarks/RESULTS.md, "`carry_map_cost`".
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI

__all__ = ["CarriedSpace", "ComplianceKernel"]

# kernel values gathered at a time (one int64 index and one float32 value each)
_BLOCK = 1 << 20


class ComplianceKernel:
    """c(x), the compliance's response to a unit pressure at the origin, on the whole N x N grid of
    every rank (one FFT pair and an allgather of N^2 float32: 64 MB at 4096^2; float32 as the carried
    products).  Units: h_rms per sigma0 (nondimensional, operator.py)."""

    def __init__(self, op):
        fft = op.fft
        self.N = N = fft.N
        local = np.ascontiguousarray(op.compliance_response(), dtype=np.float32)
        self.values = np.empty(N * N, dtype=np.float32)
        counts, displs = fft._counts()
        fft.comm.Allgatherv(local, [self.values, counts, displs, MPI.FLOAT])

    @staticmethod
    def bytes(N):
        return 4.0 * float(N) * float(N)

    @classmethod
    def fits(cls, N, settings):
        """Whether an N x N grid's steps may map (SolverSettings: carry_directions and carry_map_cost
        above 0, and the kernel within half of carry_memory: up to N = 6123 by default)."""
        return (settings.carry_directions > 0 and settings.carry_map_cost > 0
                and cls.bytes(N) <= 0.5 * settings.carry_memory)

    def block(self, xi, xj, yi, yj):
        """c(x - y) for the points x (rows) and y (columns), global grid coordinates (int arrays)."""
        N = self.N
        k = ((xi[:, None] - yi[None, :]) % N) * N
        k += (xj[:, None] - yj[None, :]) % N
        return np.take(self.values, k)


def _coordinates(fft, idx):
    """Global (row, column) of the flat local points ``idx``."""
    i, j = np.divmod(idx, fft.N)
    return i + fft.row_start, j


class CarriedSpace:
    """Directions ``U`` (rows, each zero-sum over the set) on the flat local points ``idx`` of a contact
    set, and their raw products ``W`` = (c U)_C before the mean's removal (float32): the last step's own
    first, then those it carried.
    Collective methods take the step's SlabFFT."""

    def __init__(self, idx, U, W):
        self.idx, self.U, self.W = idx, U, W

    @property
    def size(self):
        return self.U.shape[0]

    @staticmethod
    def count(n_loc, work_itemsize, directions, memory):
        """How many directions to keep: at most ``directions``, within ``memory`` bytes a rank (each in
        the work dtype, its float32 product and, while a step runs, its orthonormalised pair)."""
        per = max(int(n_loc), 1) * 2 * (work_itemsize + 4)
        return max(0, min(int(directions), int(memory // per)))

    @classmethod
    def after_solve(cls, gm, means, idx, count, basis=None, older=None):
        """The directions after a flexible SingleGMRES solve ``gm`` on the local points ``idx``: its last
        cycle's z (the first ``count``) with their raw products, A z from the Arnoldi relation plus the
        carried part C E (``basis``: the _Basis the solve carried, or None) plus the ``means`` the
        operator's P removed (one per product, the last cycle's last); then the directions of
        ``older`` (a CarriedSpace on the same set: the carried ones), ``count`` in all."""
        k, G = gm.arnoldi
        m = min(k, count)
        extra = 0 if older is None else min(older.size, count - m)
        n = gm.Z.shape[1]
        U = np.empty((m + extra, n), dtype=gm.Z.dtype)     # each row written once (no concatenation)
        W = np.empty((m + extra, n), dtype=np.float32)
        U[:m] = gm.Z[:m]
        Gt = np.ascontiguousarray(G[:, :m].T, dtype=np.float32)
        np.matmul(Gt, gm.V[:k + 1], out=W[:m])             # A z_j = sum_i G[i, j] V[i] (+ C E)
        if basis is not None and basis.size:
            W[:m] += np.ascontiguousarray(gm.projected[:, :m].T, dtype=np.float32) @ basis.C
        W[:m] += np.asarray(means[len(means) - k:len(means) - k + m], dtype=np.float32)[:, None]
        if extra:
            U[m:] = older.U[:extra]
            W[m:] = older.W[:extra]
        return cls(idx, U, W)

    # ------------------------------------------------------------------ the map to a new set
    @staticmethod
    def changed(fft, old, new):
        """Points (all ranks) that left or joined between the local sets ``old`` and ``new``."""
        po, _ = _match(old, new)
        return fft.comm.allreduce(int(old.size + new.size - 2 * po.size), op=MPI.SUM)

    def mapped(self, fft, new, n_new, kernel, ones_product):
        """The directions on the new set ``new`` (flat local points, ``n_new`` on all ranks), as above.
        ``ones_product``: (c 1_C)_C on the new set (float64, local points).  Collective."""
        comm = fft.comm
        old = self.idx
        po, pn = _match(old, new)
        left = _others(old.size, po)
        joined = _others(new.size, pn)
        k = self.size
        U = np.zeros((k, new.size), dtype=self.U.dtype)
        W = np.zeros((k, new.size), dtype=np.float32)
        for (so, eo), (sn, en) in _runs(po, pn):       # the common points: runs of the two sets
            U[:, sn:en] = self.U[:, so:eo]
            W[:, sn:en] = self.W[:, so:eo]
        # the left points' columns, out of the common points' products
        li, lj = _coordinates(fft, old[left])
        gathered = comm.allgather((li, lj, np.ascontiguousarray(self.U[:, left].T, dtype=np.float64)))
        Li, Lj, uL = (np.concatenate(a) for a in zip(*gathered))
        ci, cj = _coordinates(fft, new)       # (the joined points' rows get theirs below)
        if Li.size:
            for s, e in _blocks(new.size, Li.size):
                W[:, s:e] -= (kernel.block(ci[s:e], cj[s:e], Li, Lj) @ uL).T.astype(np.float32)
        # the joined points' rows, summed over the common points of every rank (U is 0 on the joined)
        ji, jj = _coordinates(fft, new[joined])
        gathered = comm.allgather((ji, jj))
        Ji, Jj = (np.concatenate(a) for a in zip(*gathered))
        if Ji.size:
            rows = np.zeros((Ji.size, k))
            for s, e in _blocks(new.size, Ji.size):
                rows += kernel.block(Ji, Jj, ci[s:e], cj[s:e]) @ U[:, s:e].T.astype(np.float64)
            rows = fft._allsum(rows)
            first = sum(g[0].size for g in gathered[:comm.rank])
            W[:, joined] = rows[first:first + joined.size].T
        # zero sum over the new set
        mu = fft._allsum(U.sum(axis=1, dtype=np.float64)) / n_new
        ones32 = ones_product.astype(np.float32)
        for i in range(k):
            U[i] -= U.dtype.type(mu[i])
            W[i] -= np.float32(mu[i]) * ones32
        return CarriedSpace(new, U, W)

    # ------------------------------------------------------------------ GCRO's basis
    def basis(self, fft, n_S, drop):
        """(U, C): combinations of the directions whose products C = P W are orthonormal (float32 rows),
        U the same combinations of the directions.  Combinations whose eigenvalue of the Gram matrix of
        the unit products is below ``drop`` times the largest are left out (their float32 products would
        be amplified).  Collective."""
        mean = fft._allsum(self.W.sum(axis=1, dtype=np.float64)) / n_S
        G = np.zeros((self.size, self.size))
        for s, e in _blocks(self.W.shape[1], self.size):
            blk = self.W[:, s:e].astype(np.float64) - mean[:, None]
            G += blk @ blk.T
        G = fft._allsum(G)
        d = np.sqrt(np.diag(G))
        d = np.divide(1.0, d, out=np.zeros_like(d), where=d > 0)   # unit products first: the directions'
        lam, Q = np.linalg.eigh(G * np.outer(d, d))                  # lengths span many decades
        keep = lam > drop * lam[-1] if lam.size and lam[-1] > 0 else np.zeros(lam.size, dtype=bool)
        T = (Q[:, keep] / np.sqrt(lam[keep])).T * d[None, :]         # rows: the combinations
        C = np.empty((T.shape[0], self.W.shape[1]), dtype=np.float32)
        for s, e in _blocks(self.W.shape[1], self.size):
            C[:, s:e] = T @ (self.W[:, s:e].astype(np.float64) - mean[:, None])
        U = (T.astype(self.U.dtype) @ self.U) if T.shape[0] else np.zeros((0, self.U.shape[1]), self.U.dtype)
        return _Basis(self.idx, U, C)


class _Basis:
    """GCRO's carried pair on the set ``idx``: U (work dtype) and C = A U orthonormal (float32)."""

    def __init__(self, idx, U, C):
        self.idx, self.U, self.C = idx, U, C

    @property
    def size(self):
        return self.U.shape[0]


def _match(old, new):
    """Positions (po, pn) of the points common to the sorted index arrays ``old`` and ``new``."""
    pos = np.searchsorted(new, old)
    hit = pos < new.size
    hit[hit] = new[pos[hit]] == old[hit]
    return np.flatnonzero(hit), pos[hit]


def _others(n, positions):
    """The positions in range(n) not in ``positions``."""
    mask = np.ones(n, dtype=bool)
    mask[positions] = False
    return np.flatnonzero(mask)


def _runs(po, pn):
    """((start, stop) in old, (start, stop) in new) of the runs where both position arrays step by one."""
    if po.size == 0:
        return []
    cut = np.flatnonzero((np.diff(po) != 1) | (np.diff(pn) != 1)) + 1
    starts = np.concatenate([[0], cut])
    stops = np.concatenate([cut, [po.size]])
    return [((po[a], po[b - 1] + 1), (pn[a], pn[b - 1] + 1)) for a, b in zip(starts, stops)]


def _blocks(n, width):
    """(start, stop) of consecutive ranges of n rows, about _BLOCK / width rows each."""
    step = max(1, _BLOCK // max(int(width), 1))
    return [(s, min(s + step, n)) for s in range(0, n, step)]
