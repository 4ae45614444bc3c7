"""Polonsky & Keer (1999, Wear 231, 206-219) constrained conjugate gradients, load control.

Elastic only (the operator must be symmetric positive: Im E(q_x v) = 0 on the grid).  The unknown is
the nondimensional pressure p^ >= 0 with mean(p^) = 1; u = c p^ (c = 1/m, the compliance) and the gap
g^ = u - h^ + delta, with delta fixed at every iteration by mean over the contact set of g^ = 0
(as in Tamaas' PolonskyKeerRey).

FFT pairs: the conjugate direction needs c t (one pair per iteration).  The displacement u = c p^ is
updated by the recursion u <- s (u - tau c t) when the projection step changed nothing (no clipped
point, no re-entering point); otherwise it is recomputed from p^ (one more pair).  Before declaring
convergence u is always recomputed from scratch (a fresh pair) and the measures re-checked.
The convergence measures and tolerance are those of the SNES solver (see operator.py).
"""
from __future__ import annotations

import numpy as np
from mpi4py import MPI

__all__ = ["pk_solve", "allsum", "allmax"]


def allsum(comm, values):
    """Sum over ranks of a list of floats, bitwise identical everywhere (Reduce + Bcast)."""
    v = np.ascontiguousarray(values, dtype=np.float64)
    if comm.size == 1:
        return v.copy()
    out = np.empty_like(v)
    comm.Reduce(v, out, op=MPI.SUM, root=0)
    comm.Bcast(out, root=0)
    return out


def allmax(comm, values):
    v = np.ascontiguousarray(values, dtype=np.float64)
    if comm.size == 1:
        return v.copy()
    out = np.empty_like(v)
    comm.Allreduce(v, out, op=MPI.MAX)
    return out


def pk_solve(op, tol=1e-8, max_iter=20000, p0=None, monitor=None):
    """Solve the elastic contact problem of ``op`` (a ContactOperator) by Polonsky-Keer CG.

    Returns (phat, ghat, info) with info = dict(iterations, converged, residual, measures, reason).
    """
    fft = op.fft
    comm = fft.comm
    n2 = float(op.N) ** 2
    kappa = op.kappa
    c = op.c
    hhat = op.hhat
    if p0 is None:
        p = fft.real_array()
        p[...] = 1.0
    else:
        p = np.maximum(np.asarray(p0, dtype=float), 0.0)
        s = fft.sum(p) / n2
        p = p / s if s > 0 else np.ones_like(p)
    u = fft.apply(p, c)
    fresh = True
    t = fft.real_array()
    g = fft.real_array()
    r = fft.real_array()
    G_old = 1.0
    conj = False
    reason = "max_iterations"
    converged = False
    measures = (np.inf, np.inf, np.inf)
    it = 0
    while True:
        S = p > 0
        np.subtract(u, hhat, out=g)
        nS, sg = allsum(comm, [np.count_nonzero(S), np.sum(g, where=S)])
        if nS == 0:  # cannot happen with mean(p) = 1, but never divide by zero
            reason = "empty_contact_set"
            break
        g -= sg / nS
        # measures of the current iterate
        comp = np.abs(np.minimum(p, kappa * g)).max()
        pen = max(float((-g).max()), 0.0)
        cm, pm = allmax(comm, [comp, pen])
        force = abs(fft.sum(p) / n2 - 1.0)
        measures = (float(cm), float(pm), float(force))
        res = max(measures)
        if monitor is not None:
            monitor(it, res)
        if res <= tol:
            if fresh:
                converged = True
                reason = "converged"
                break
            u = fft.apply(p, c, u)
            fresh = True
            continue
        if it >= max_iter:
            break
        it += 1
        G = allsum(comm, [np.sum(g * g, where=S)])[0]
        if conj and G_old > 0:
            beta = G / G_old
            np.multiply(t, beta, out=t)
            t += g
            t[~S] = 0.0
        else:
            np.copyto(t, g)
            t[~S] = 0.0
        G_old = G
        fft.apply(t, c, r)
        rbar = allsum(comm, [np.sum(r, where=S)])[0] / nS
        num, den = allsum(comm, [np.sum(g * t, where=S), np.sum((r - rbar) * t, where=S)])
        if not den > 0:
            reason = "breakdown"
            break
        tau = num / den
        pn = p - tau * t
        neg = pn < 0
        pn[neg] = 0.0
        Iol = (~S) & (g < 0)
        pn[Iol] = -tau * g[Iol]
        nneg, nol, psum = allsum(comm, [np.count_nonzero(neg), np.count_nonzero(Iol), np.sum(pn)])
        conj = nol == 0
        if not psum > 0:
            reason = "breakdown"
            break
        s = n2 / psum
        pn *= s
        if nneg == 0 and nol == 0:
            # u_new = c p_new = s (u - tau c t)
            u -= tau * r
            u *= s
            fresh = False
        else:
            fft.apply(pn, c, u)
            fresh = True
        p = pn
    # final gap consistent with p (u is fresh whenever converged)
    return p, g, dict(iterations=it, converged=converged, residual=max(measures), measures=measures,
                      reason=reason)
