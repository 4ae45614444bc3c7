"""The local edge correction of the contact-set steps' preconditioner (contactset.py).

The contact-set step solves A y = b with A = P c_CC P, preconditioned by B = P m_CC P (c = 1/m).  On the
whole grid m = c^-1, and for a subset C the exact inverse is the Schur complement

    (c_CC)^-1 = m_CC - m_CF (m_FF)^-1 m_FC,

so B errs only near the contact edges, where m_CF is large: that is where the inner iterations go
(RESULTS.md, "Growth of the oracle solve").  This module adds a local estimate of the missing term.
For a contact point i with a free point within ``w`` grid points (Chebyshev), W the (2w+1)^2 window
centred on i, C_W and F_W its contact and free points:

    (B_edge r)_i = (B r)_i - sum_{j in C_W} [ M_iF (M_FF)^-1 M_FC ]_ij r_j      (M on W, F = F_W, C = C_W)

with one of two local stand-ins M for the stiffness (``rows``):

- ``"inverse"``: M = inv(c_W), the inverse of the compliance on the whole window.  The row is then the
  centre row of inv(c on C_W) minus that of inv(c_W) (the same identity): the local inverse on the
  window's contact points, less the window's own edges.  It treats every point outside W as free.
- ``"schur"``: M = m_W, the stiffness's own kernel on the window: the exact Schur complement with the
  free set cut to F_W, every point outside W counted in contact.

Away from the edges the term vanishes in both.  The local inverses cut more iterations where they
work, but at a high modulus range (fast sliding, a broad glass transition) they can make B indefinite
and the steps stall; the Schur rows never did, and take the place of the local inverses there
(SolverSettings.edge_rows; RESULTS.md, "Edge rows from the stiffness").  The rows depend only on which
window points are in contact (a mask of (2w+1)^2 bits), so one small dense solve is made per mask and
grid (for the local inverses on the smaller of C_W and F_W), and reused by every later Newton step on
that grid.  Applying the term is one sparse product on C (no FFT pair) and, on several ranks, an
exchange of the contact values in w rows with each neighbouring slab; the set-up costs one FFT pair
per grid (the kernel of c, or of m).

Units: nondimensional (operator.py); the term maps a gap error on C (h_rms) to a pressure (sigma0).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from mpi4py import MPI
from scipy.sparse import _sparsetools

from vecontact.solver.subset import gather

__all__ = ["EdgeCorrection"]


class EdgeCorrection:
    """The edge term of one grid's contact-set preconditioner: ``build(act, idx)`` for each new contact
    set (collective), then ``apply(x)`` (collective) returns the term for a C-vector x, and
    ``add_to(x, y)`` (collective) adds it to y without a new array.

    ``op``: the ContactOperator of the grid; ``w``: the window's half width (grid points, >= 1);
    ``drop``: a row's entries below this fraction of its largest are dropped; ``headroom``: the kept
    vectors of ``apply`` and ``add_to`` are made this much longer than a set needs; ``rows``: the
    stand-in for the stiffness on a window, "inverse" (inv(c_W)) or "schur" (m_W; module docstring).
    ``usable`` is False on a grid smaller than the window or where a rank holds fewer than w rows (the
    halo would span several slabs): the step then runs without the term (the same answer, more
    iterations)."""

    ROWS = ("inverse", "schur")

    def __init__(self, op, w, drop, headroom=0.0, rows="inverse"):
        if rows not in self.ROWS:
            raise ValueError(f"edge rows {rows!r}: expected one of {', '.join(self.ROWS)}")
        self.rows = rows
        self.op = op
        self.fft = fft = op.fft
        self.comm = fft.comm
        self.w = w = int(w)
        self.drop = float(drop)
        self.headroom = float(headroom)
        a, b = np.divmod(np.arange((2 * w + 1) ** 2), 2 * w + 1)
        self.da, self.db = a - w, b - w                      # window offsets (rows, columns), centre K // 2
        if not 1 <= w <= 3:
            raise ValueError(f"edge window half width {w}: expected 1, 2 or 3 (a window's mask is one int64)")
        # a window must not wrap onto itself, nor a halo span more than one neighbouring slab
        self.usable = 2 * w + 1 <= fft.N and self.comm.allreduce(fft.nrows, op=MPI.MIN) >= w
        self._base = None                                    # (the kernel on the window, M): _kernel_table
        self._codes = np.zeros(0, dtype=np.int64)            # masks seen on this grid, sorted
        self._rows = np.zeros((0, self.da.size))             # their correction rows
        self.S = None
        self._x = self._term = np.zeros(0)
        self._on_rows = {}                                   # add_to's y on the edge rows, by dtype
        self._act = None                                     # the contact set of the last build

    # ------------------------------------------------------------------ set-up
    def _kernel_table(self):
        """(k_W, M): the kernel on the window (K x K over its points; c's or m's, by ``rows``) and M, the
        stiffness's stand-in there: inv(c_W) or m_W itself.  One FFT pair: the kernel's response to a
        unit at the origin, its values at the offsets |d| <= 2w gathered to every rank."""
        if self._base is None:
            fft, w, N = self.fft, self.w, self.fft.N
            if self.rows == "inverse":
                kern = self.op.compliance_response()
            else:
                kern = self.op.stiffness_response()
            off = np.arange(-2 * w, 2 * w + 1)
            table = np.zeros((off.size, off.size))
            for i, r in enumerate(off % N):
                if fft.row_start <= r < fft.row_stop:
                    table[i] = kern[r - fft.row_start, off % N]
            self.comm.Allreduce(MPI.IN_PLACE, table, op=MPI.SUM)
            kW = table[(self.da[:, None] - self.da[None, :]) + 2 * w, (self.db[:, None] - self.db[None, :]) + 2 * w]
            self._base = (kW, np.linalg.inv(kW) if self.rows == "inverse" else kW)
        return self._base

    def _correction_rows(self, codes):
        """The correction row of each window mask in ``codes`` (sorted, unique): solved for the masks
        not seen before on this grid, then looked up."""
        known = self._codes
        new = codes[~np.isin(codes, known)] if known.size else codes
        if new.size:
            K = self.da.size
            mask = ((new[:, None] >> np.arange(K)) & 1).astype(bool)
            rows = self._solve_masks(mask)
            # the small entries cost products and save no iterations [RESULTS.md]
            big = np.abs(rows).max(axis=1, keepdims=True)
            rows[np.abs(rows) < self.drop * big] = 0.0
            allc = np.concatenate([known, new])
            order = np.argsort(allc, kind="stable")
            self._codes = allc[order]
            self._rows = np.concatenate([self._rows, rows])[order]
        return self._rows[np.searchsorted(self._codes, codes)]

    def _solve_masks(self, mask):
        """The correction rows of the window masks ``mask`` (n x K bool, the centre in contact), before
        the drop: the centre row of -M_CF inv(M_FF) M_FC on the mask's contact points C (zero on its
        free points F; an edge point has at least one).  Masks of one size are solved together.  For
        the local inverses (M = inv(c_W)) the same row is the centre row of inv(c_CC) minus that of M
        on C, solved on the p contact points where they are the fewer (c_CC^T x = e_centre)."""
        kW, M = self._kernel_table()
        K = M.shape[0]
        centre = K // 2
        rows = np.zeros(mask.shape)
        p = mask.sum(axis=1)
        for size in np.unique(p):
            g = np.flatnonzero(p == size)
            C = np.nonzero(mask[g])[1].reshape(g.size, size)        # each mask's contact points, sorted
            if self.rows == "inverse" and size <= K - size:
                x = np.linalg.solve(kW.T[C[:, :, None], C[:, None, :]], (C == centre)[..., None].astype(float))
                rows[g[:, None], C] = x[..., 0] - M[centre][C]
            else:
                F = np.nonzero(~mask[g])[1].reshape(g.size, K - size)
                z = np.linalg.solve(M.T[F[:, :, None], F[:, None, :]], M[centre][F][..., None])
                rows[g[:, None], C] = -np.einsum("nf,nfc->nc", z[..., 0], M[F[:, :, None], C[:, None, :]])
        return rows

    def _halo(self, send_prev, send_next, recv_prev, recv_next):
        """recv_prev = the previous slab's send_next, recv_next = the next slab's send_prev (periodic)."""
        comm = self.comm
        if comm.size == 1:
            recv_prev[...] = send_next
            recv_next[...] = send_prev
            return
        prev, nxt = (comm.rank - 1) % comm.size, (comm.rank + 1) % comm.size
        comm.Sendrecv(send_prev, dest=prev, sendtag=71, recvbuf=recv_next, source=nxt, recvtag=71)
        comm.Sendrecv(send_next, dest=nxt, sendtag=72, recvbuf=recv_prev, source=prev, recvtag=72)

    def build(self, act, idx):
        """The term for the contact set ``act`` (bool, local rows), ``idx`` its flat local points
        (sorted): the sparse rows of the edge points and the halo plan of ``apply``.  Nothing to do
        when the set is the last build's on every rank (the exact Newton steps)."""
        if not self.usable:
            self.S = None
            return
        self._kernel_table()       # collective: here on every rank, not only on those with new masks
        # an exact Newton step's set is the last step's: S stands (collective: every rank must skip)
        same = self._act is not None and np.array_equal(act, self._act)
        if self.comm.size > 1:
            same = self.comm.allreduce(same, op=MPI.LAND)
        if same:
            return
        self._act = act.copy()
        w, N = self.w, self.fft.N
        n = act.shape[0]
        side = 2 * w + 1
        rows = np.empty((n + 2 * w, N), dtype=np.uint8)      # act with w halo rows above and below
        rows[w:w + n] = act
        self._halo(rows[w:2 * w], rows[n:n + w], rows[:w], rows[n + w:])
        ext = np.concatenate([rows[:, N - w:], rows, rows[:, :w]], axis=1)   # + w columns each side
        Ne = N + 2 * w
        # each point's row of its window as side bits (bit b: column offset b - w; side <= 7: uint8)
        rc = ext[:, :N].copy()
        for b in range(1, side):
            rc |= ext[:, b:b + N] << b
        # the edge points: contact points whose window is not all in contact
        whole = (1 << side) - 1
        inner = rc[:n] == whole
        for a in range(1, side):
            inner &= rc[a:a + n] == whole
        edge = np.flatnonzero(act.ravel() > inner.ravel())
        ie, je = np.divmod(edge, N)
        base = (ie + w) * Ne + je + w                        # the edge points in the padded grid
        # each edge point's window mask as an integer, bit a*side + b for the offset (a - w, b - w)
        kind = np.int32 if side * side < 31 else np.int64
        codes = np.zeros(edge.size, dtype=kind)
        for a in range(side):
            codes |= np.left_shift(rc[a:a + n].ravel()[edge], side * a, dtype=kind)
        offsets = self.da * Ne + self.db                    # the window's points in the padded grid
        # positions in the extended C-vector: local C, then the halo rows' contact points (row-major)
        pos = np.full(ext.shape, -1, dtype=np.int32)
        core = pos[:, w:w + N]
        n_prev, n_next = int(np.count_nonzero(rows[:w])), int(np.count_nonzero(rows[n + w:]))
        core[w:w + n][act] = np.arange(idx.size, dtype=np.int32)
        core[:w][rows[:w].view(bool)] = np.arange(idx.size, idx.size + n_prev, dtype=np.int32)
        core[n + w:][rows[n + w:].view(bool)] = np.arange(idx.size + n_prev, idx.size + n_prev + n_next,
                                                          dtype=np.int32)
        pos[:, :w] = pos[:, N:N + w]
        pos[:, N + w:] = pos[:, w:2 * w]
        pos = pos.ravel()
        # the kept entries of each mask's row, then of each edge point's (only they are gathered)
        srt = np.sort(codes)                # np.unique: the same, 1.7x slower (RESULTS.md)
        uniq = srt[np.concatenate(([True], srt[1:] != srt[:-1]))] if srt.size else srt
        vals = self._correction_rows(uniq)
        keep = vals != 0.0
        per_mask = keep.sum(axis=1)
        first = np.cumsum(per_mask) - per_mask
        at_kind = np.int32 if ext.size < 2 ** 31 else np.int64
        kept_off = offsets.astype(at_kind)[np.nonzero(keep)[1]]   # every mask's kept entries, in order
        which = np.searchsorted(uniq, codes)
        count = per_mask[which]
        # S has a row per edge point only (the rest of C has no term): a product need not pass over
        # |C| rows, nor an add over |C| entries [RESULTS.md]
        indptr = np.zeros(edge.size + 1, dtype=np.int32)
        np.cumsum(count, out=indptr[1:])      # int32: S has far fewer than 2**31 entries on a rank
        # entry j of S: kept entry src[j] (of its row's mask), at its row's point plus the entry's offset
        src = np.arange(indptr[-1], dtype=np.int32) - np.repeat(indptr[:-1] - first[which], count)
        at = np.repeat(base.astype(at_kind), count)
        at += kept_off[src]
        self.S = sp.csr_matrix((vals[keep][src], pos[at], indptr), shape=(edge.size, idx.size + n_prev + n_next))
        self._edge_rows = pos[base].astype(np.intp)          # the edge points' C positions (ascending)
        # the halo plan: local contact points in the first and last w rows, and where theirs go
        self._first = int(np.searchsorted(idx, w * N))
        self._last = int(idx.size - np.searchsorted(idx, (n - w) * N))
        self._x = self._room(self._x, idx.size + n_prev + n_next)
        self._term = self._room(self._term, edge.size)    # add_to's product
        self._n = idx.size
        self._n_prev = n_prev

    def _extended(self, x):
        """x with the neighbouring slabs' contact values of the halo rows appended (float64)."""
        xe, n = self._x, self._n
        xe[:n] = x
        self._halo(xe[:self._first], xe[n - self._last:n], xe[n:n + self._n_prev], xe[n + self._n_prev:])
        return xe

    def _room(self, a, n, dtype=np.float64):
        """``a``'s first n entries, or a new array (of ``dtype``) with headroom when it is shorter or
        None: the next sets' sizes differ by a little, and a new array's pages fault in again."""
        if a is not None and a.base is not None:
            a = a.base
        if a is None or a.size < n:
            a = np.empty(int(n * (1.0 + self.headroom)) + 1, dtype=dtype)
        return a[:n]

    def apply(self, x):
        """The edge term (float64, C-vector) of the C-vector ``x`` (any float dtype); None without one."""
        if self.S is None:
            return None
        term = np.zeros(self._n)
        term[self._edge_rows] = self.S @ self._extended(x)
        return term

    def add_to(self, x, y):
        """y += the edge term of the C-vector ``x`` (y of any float dtype: the float64 term rounded to
        it, as np.add(y, apply(x), out=y) does, bit for bit on the edge rows; y elsewhere is left as it
        is, where that add would turn a -0.0 into 0.0); nothing without a term.  The product,
        and y's values on the edge rows, go into arrays kept with the set: a large grid's new array a
        call cost its page faults, half of the product's time on a 4096² grid [RESULTS.md]."""
        if self.S is None:
            return
        S, t, rows = self.S, self._term, self._edge_rows
        t.fill(0.0)                     # csr_matvec adds to its output, as S @ x's own zeros
        _sparsetools.csr_matvec(S.shape[0], S.shape[1], S.indptr, S.indices, S.data, self._extended(x), t)
        kept = self._on_rows.get(y.dtype)
        kept = self._on_rows[y.dtype] = self._room(kept, rows.size, y.dtype)
        gather(y, rows, kept)
        np.add(kept, t, out=kept, casting="same_kind")
        y[rows] = kept
