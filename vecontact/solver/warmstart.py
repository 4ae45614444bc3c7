"""Warm starts: grid transfers (coarse grids) and reuse of a previous solution.

Grid transfer is spectral: the Fourier modes common to both grids are copied (|kx| < n/2, ky < n/2 with
n the smaller grid size, i.e. the Nyquist row/column of the smaller grid is dropped), everything else is
zero.  Restriction of a band-limited surface (the paper's null band: no roughness above N/16) is
therefore exact (identical to sampling h[::2, ::2]); prolongation is trigonometric interpolation.
The Fourier layouts of the two SlabFFTs (ky-column slabs) generally differ: the columns are
redistributed with one MPI Alltoallv.
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI

from vecontact.core.pfft import SlabFFT

__all__ = ["fourier_transfer", "transfer_real", "coarse_fft", "coarse_levels"]

_FFT_CACHE = {}


def coarse_fft(fft, n):
    """A SlabFFT of size n on the same communicator (cached per communicator, size, threads, planner and
    wisdom file: a fine grid with another wisdom file gets coarse grids that save into that file)."""
    wisdom = getattr(fft, "wisdom_file", None) or False
    key = (id(fft.comm), fft.comm.size, int(n), fft.threads, fft.planner, wisdom)
    f = _FFT_CACHE.get(key)
    if f is None or f.comm is not fft.comm:
        f = SlabFFT(fft.comm, int(n), threads=fft.threads, planner=fft.planner, wisdom_file=wisdom)
        _FFT_CACHE[key] = f
    return f


def coarse_levels(N, size, min_n, max_levels):
    """Coarse grid sizes (coarsest first) below N: N/2, N/4, ... while >= min_n (and >= 2 rows per
    rank of ``size``) and even, at most ``max_levels`` of them."""
    levels = []
    n = N
    while len(levels) < max_levels and n % 2 == 0 and n // 2 >= min_n and n // 2 >= 2 * size:
        n //= 2
        levels.append(n)
    return levels[::-1]


def _kx_rows(n_small, N):
    """Row indices (in a grid of size N) of kx with |kx| < n_small/2, canonical order."""
    kmax = (n_small - 1) // 2  # |kx| <= kmax  <=>  |kx| < n_small/2
    kx = np.concatenate([np.arange(0, kmax + 1), np.arange(-kmax, 0)])
    return kx % N


def _layout(f):
    """[(col_start, col_stop)] of every rank (the SlabFFT's own column split, whatever it is)."""
    lay = getattr(f, "_vc_cols", None)
    if lay is None:
        lay = f.comm.allgather((int(f.col_start), int(f.col_stop)))
        try:
            f._vc_cols = lay
        except Exception:
            pass
    return lay


def fourier_transfer(src, F, dst, out=None):
    """Move a Fourier array ``F`` of SlabFFT ``src`` to the layout of SlabFFT ``dst`` (same comm).

    Values are scaled by (N_dst/N_src)^2 so that the field (backward transform) is preserved.
    """
    comm = src.comm
    P = comm.size
    Ns, Nd = src.N, dst.N
    n = min(Ns, Nd)
    kymax = (n - 1) // 2  # ky <= kymax
    rows_s = _kx_rows(n, Ns)
    rows_d = _kx_rows(n, Nd)
    nk = rows_s.size
    scale = (float(Nd) / float(Ns)) ** 2
    if out is None:
        out = dst.fourier_array()
    else:
        out[...] = 0.0
    cs = _layout(src)
    cd = _layout(dst)
    me = comm.rank

    def inter(a, b):
        lo, hi = max(a[0], b[0]), min(a[1], b[1], kymax + 1)
        return lo, max(lo, hi)

    # send: my src columns that rank r holds in dst
    send_parts, scounts = [], []
    for r in range(P):
        lo, hi = inter(cs[me], cd[r])
        if hi > lo:
            blk = F[rows_s][:, lo - cs[me][0]:hi - cs[me][0]]
            send_parts.append(np.ascontiguousarray(blk).ravel())
            scounts.append(blk.size)
        else:
            scounts.append(0)
    rcounts, rranges = [], []
    for r in range(P):
        lo, hi = inter(cs[r], cd[me])
        rcounts.append(nk * (hi - lo))
        rranges.append((lo, hi))
    if P == 1:
        recv = send_parts[0] if send_parts else np.zeros(0, complex)
    else:
        sbuf = np.concatenate(send_parts) if send_parts else np.zeros(0, complex)
        rbuf = np.empty(sum(rcounts), dtype=complex)
        sd = np.concatenate([[0], np.cumsum(scounts)[:-1]]).astype(int)
        rd = np.concatenate([[0], np.cumsum(rcounts)[:-1]]).astype(int)
        comm.Alltoallv([sbuf, (scounts, sd), MPI.C_DOUBLE_COMPLEX],
                       [rbuf, (rcounts, rd), MPI.C_DOUBLE_COMPLEX])
        recv = rbuf
    off = 0
    for r in range(P):
        lo, hi = rranges[r]
        if hi > lo:
            blk = recv[off:off + nk * (hi - lo)].reshape(nk, hi - lo)
            out[rows_d, lo - cd[me][0]:hi - cd[me][0]] = blk * scale
            off += nk * (hi - lo)
    return out


def transfer_real(src, f, dst):
    """Spectral transfer of a real field (local rows of ``src``) to the grid of ``dst``."""
    F = src.forward(f)
    G = fourier_transfer(src, F, dst)
    return dst.backward(G)


def bearing_guess(op, area_min, area_max, tol, area=None):
    """Cold-start gap (nondimensional) of a rigid flat at the height that cuts the fraction ``area``
    of the surface: g^ = max(delta - h^, 0), delta by bisection to ``tol`` (h_rms).  Default ``area``:
    Persson's estimate erf(sqrt(2) (1 - nu^2) sigma0 / X) with X^2 = sum_q |q|^2 |E(q_x v)|^2 |h_q|^2 (the
    grid version of E0 xi(v) of docs/conventions.md §5), clipped to [area_min, area_max]."""
    import math
    fft = op.fft
    N = op.N
    if area is None:
        w = fft.half_weights()
        hq2 = (op.h_fourier.real ** 2 + op.h_fourier.imag ** 2) / float(N) ** 4
        dens = op.q ** 2 * (op.E.real ** 2 + op.E.imag ** 2) * hq2
        X2 = fft.sum(np.array([np.sum(dens.sum(axis=0) * w[0])]))
        if X2 > 0:
            area = math.erf(math.sqrt(2.0) * (1.0 - op.nu ** 2) * op.sigma0 / math.sqrt(X2))
        else:
            area = 1.0
        area = min(max(area, area_min), area_max)
    hh = op.hhat
    lo = fft.comm.allreduce(float(hh.min()) if hh.size else np.inf, op=MPI.MIN)
    hi = fft.comm.allreduce(float(hh.max()) if hh.size else -np.inf, op=MPI.MAX)
    n2 = float(N) ** 2
    while hi - lo >= tol:   # False for NaN heights too
        mid = 0.5 * (lo + hi)
        if not lo < mid < hi:   # the floating-point resolution of the heights is reached
            break
        frac = fft.comm.allreduce(int(np.count_nonzero(hh >= mid)), op=MPI.SUM) / n2
        if frac > area:
            lo = mid
        else:
            hi = mid
    g = np.maximum(hi - hh, 0.0)
    return g


def prolong_gap(src_op, ghat, phat, dst_op):
    """Initial nondimensional gap on dst's grid from a solution (ghat, phat) on src's grid:
    trigonometric interpolation of the gap and the pressure; contact where the interpolated pressure
    exceeds kappa x interpolated gap (gap 0 there), elsewhere the interpolated gap clamped at 0."""
    sf, df = src_op.fft, dst_op.fft
    gi = df.backward(fourier_transfer(sf, sf.forward(ghat * src_op.ell), df))
    gi *= 1.0 / dst_op.ell
    pi = df.backward(fourier_transfer(sf, sf.forward(phat * src_op.sigma0), df))
    pi *= 1.0 / dst_op.sigma0
    return np.where(pi > dst_op.kappa * gi, 0.0, np.maximum(gi, 0.0))


def chebyshev_nodes(lo, hi, n):
    """The n Chebyshev nodes of [lo, hi], largest first: lambda_k = (hi + lo) / 2 + (hi - lo) / 2
    cos(pi (2 k + 1) / (2 n)), k = 0 .. n - 1."""
    k = np.arange(int(n))
    return 0.5 * (hi + lo) + 0.5 * (hi - lo) * np.cos(np.pi * (2 * k + 1) / (2 * int(n)))


def smooth_gap(op, ghat, sweeps, ratio, out=None):
    """Projected Richardson sweeps on the NCP (one FFT pair each), with Chebyshev step sizes:
    g <- max(0, g - p(g) / lambda_k), k = 1 .. ``sweeps``, lambda_k the Chebyshev nodes of
    [m_max / ``ratio``, m_max] (chebyshev_nodes), m_max = max_q |m_q| (nondimensional, sigma0 per h_rms).
    Returns the smoothed gap: ``out`` if given (it may be ``ghat``), else a new array, and ``ghat``
    itself when there is nothing to do (no sweeps, or no stiffness).  The pressures go to the operator's
    scratch (``op.work``), which no caller holds across the sweeps.

    Without contact a Fourier mode of the gap's error is multiplied by prod_k (1 - m_q / lambda_k): by at
    most 1 / T_n((ratio + 1) / (ratio - 1)) (T_n the Chebyshev polynomial) for real m_q in [m_max / ratio,
    m_max], the short waves.  After a prolongation those are what the coarser grid could not carry: the
    grid-scale errors of the interpolated gap at the contact edges are damped, and the first Newton step
    sees far fewer active-set changes.  After an inexact Newton step on the free set (snes.py,
    SolverSettings.step_sweeps) they are its error near the contact edges, which would flip points in the
    next step.  A viscoelastic m_q is complex, and the large steps can then grow some modes (RESULTS.md);
    the Newton steps correct them.  The sweeps replaced session 17's 16 damped-Jacobi sweeps (fewer FFT
    pairs for the same start; RESULTS.md, "`smooth_ratio`")."""
    if sweeps <= 0:
        return ghat
    mmax = op.stiffness_bounds()[1]
    if not mmax > 0:
        return ghat
    if out is None:
        g = np.array(ghat, dtype=float, copy=True)
    else:
        g = out
        if g is not ghat:
            np.copyto(g, ghat)
    p = op.work
    for lam in chebyshev_nodes(mmax / ratio, mmax, sweeps):
        op.pressure(g, p)
        p *= 1.0 / lam              # in place: the same numbers as a temporary, no N^2 allocation
        g -= p
        np.maximum(g, 0.0, out=g)
    return g
