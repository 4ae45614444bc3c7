"""What carrying Krylov directions across the free-set Newton steps could buy: a bound, and its cost.

Usage (from the repository root):
    python benchmarks/carry_bound.py [--n 1024] [--velocity 0.01] [--sigma0 153648.9] [--carry 10,30]
                                     [--window 4] [--mode free|contact]
    mpiexec -n 2 python benchmarks/carry_bound.py --pass-cost [--n 1024] [--fraction 0.43]
    mpiexec -n 2 python benchmarks/carry_bound.py --map-cost [--n 1024] [--fraction 0.05] [--changed 10,100,1000]

**Bound** (1 rank; the paper surface of benchmarks/solver.py, seed 1, Havriliak-Negami compound). One real
solve records every free-set step of its finest grid (freeset.py: the set F, the right-hand side b, the
solution the step reached).  Each step is then solved again in float64 numpy, to the relative residual
the real step reached:

* plain: right-preconditioned GMRES on A B (A = (m P_F .)_F / kappa, B the free-set preconditioner)
  from zero, as the solver's steps;
* carry K: GCRO.  The K newest directions z of the steps before (their preconditioned vectors, the
  carried ones after the step's own), restricted to the new F, with their products C = A z: the
  solution starts from the projection of b on span C, and every later Krylov vector is kept orthogonal
  to it.  The products are formed exactly here, not counted.  With ``--window`` rho they are instead
  mapped from the last step's: m's kernel cut to a (2 rho + 1)^2 window around each point that left
  or joined F (what a solver would do: the kernel decays as 1/r^3).

``--mode contact`` does the same for the contact-set steps (contactset.py: A = P c_CC P, B = P (m_CC +
the edge correction) P, in float64 where the solver's changing steps run float32; exact products only).

The Newton trajectory is the real one, so the iterations are a bound of carrying, not a solver's.
Printed per step and in total: the iterations of the real solver, plain and each K.

**Pass cost** (``--pass-cost``, every rank at once): what the projection adds to an iteration, two
passes over K float32 vectors of a rank's free set (``--fraction`` of its grid points), against the
float64 and float32 FFT pair (medians of 20, milliseconds).

**Map cost** (``--map-cost``, every rank at once): what the solver's map of carried directions to a
changed contact set costs (recycle.CarriedSpace.mapped, K = SolverSettings.carry_directions, the set a
random ``--fraction`` of the grid, ``--changed`` points leaving and joining it in equal numbers),
against the float64 FFT pair: milliseconds, and the map's pairs per unit of |C| (changed) / N^2, the
measure SolverSettings.carry_map_cost gates by.
"""
import argparse
import json
import math
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import paper_case  # noqa: E402  (benchmarks/: the study's surfaces and compound)


def record_steps(fft, L, h, modulus, velocity, sigma0, mode="free"):
    """Solve once; return the solve's result and its finest grid's Newton steps of ``mode`` (free:
    freeset.FreeSetStep, contact: contactset.ContactSetStep) as dicts."""
    from vecontact.solver import solve_contact
    from vecontact.solver.contactset import ContactSetStep
    from vecontact.solver.freeset import FreeSetStep
    cls = FreeSetStep if mode == "free" else ContactSetStep
    steps = []
    solve = cls.solve
    own = "solve" in vars(cls)          # else inherited: put nothing back on the class afterwards

    def recording(step):
        before = step.iterations
        solve(step)
        if step.fft.N == fft.N:
            steps.append(dict(idx=step.idx.copy(), n_active=getattr(step, "n_active", 0),
                              act=~step.free if mode == "contact" else None,
                              b=step._b.getArray().copy(), y=step._y.getArray().copy(),
                              its=step.iterations - before, op=step.op, kappa=step.kappa))
    cls.solve = recording
    try:
        result = solve_contact(fft, L, h, modulus, velocity, sigma0, tolerance=1e-8, store=())
    finally:
        if own:
            cls.solve = solve
        else:
            del cls.solve
    return result, steps


class FreeSystem:
    """A and B of one free-set step (freeset.py) on 1 rank, float64."""

    def __init__(self, fft, step):
        self.fft, self.op, self.kappa = fft, step["op"], step["kappa"]
        self.idx, self.n_active = step["idx"], step["n_active"]
        self.buf, self.out = fft.real_array(), fft.real_array()

    def _product(self, x, multiplier, scale):
        self.buf[...] = 0.0
        self.buf.ravel()[self.idx] = x
        self.fft.apply(self.buf, multiplier, self.out, scale)
        return self.out.ravel()

    def A(self, x):
        return self._product(x, self.op.m, 1.0 / self.kappa)[self.idx]

    def B(self, z):
        full = self._product(z, self.op.c, self.kappa)
        y = full[self.idx]
        return y - (full.sum() - y.sum()) / self.n_active       # the rigid shift (freeset.py)


class ContactSystem(FreeSystem):
    """A = P c_CC P and B = P (m_CC + the edge correction) P of one contact-set step (contactset.py;
    P removes the mean over C) on 1 rank, float64.  ``edge``: the grid's EdgeCorrection (``edge_of``),
    built here for this step's set, as the solver does (one kernel for all the steps), or None."""

    def __init__(self, fft, step, edge):
        super().__init__(fft, step)
        self.edge = edge
        if edge is not None:
            edge.build(step["act"], self.idx)

    def A(self, x):
        y = self._product(x, self.op.c, 1.0)[self.idx]
        return y - y.mean()

    def B(self, z):
        y = self._product(z, self.op.m, 1.0)[self.idx]
        term = self.edge.apply(z) if self.edge is not None else None
        if term is not None:
            y += term
        return y - y.mean()


def edge_of(op):
    """The EdgeCorrection of SolverSettings' edge_window, edge_drop and edge_rows on the grid of ``op``, or None."""
    from vecontact.solver import SolverSettings
    from vecontact.solver.edge import EdgeCorrection
    st = SolverSettings()
    if st.edge_window == 0:
        return None
    return EdgeCorrection(op, st.edge_window, st.edge_drop, rows=st.edge_rows(op.modulus_range()))


def gcro(system, b, target, U=None, C=None, max_it=2000):
    """Right-preconditioned GMRES (modified Gram-Schmidt twice) on A B from x = U C^T b, every Krylov
    vector kept orthogonal to C (orthonormal, C = A U), until the least-squares residual is at most
    ``target`` |b|.  Returns (iterations, x, the directions z = B v of its own basis, columns)."""
    x = np.zeros_like(b)
    r = b.copy()
    if C is not None:
        cr = C.T @ r
        x += U @ cr
        r -= C @ cr
    beta = np.linalg.norm(r)
    nb = np.linalg.norm(b)
    if beta <= target * nb:
        return 0, x, np.zeros((b.size, 0))
    V, Z, CW = [r / beta], [], []
    H = np.zeros((max_it + 1, max_it))
    g = np.zeros(max_it + 1)
    g[0] = beta
    k = 0
    while k < max_it:
        z = system.B(V[k])
        w = system.A(z)
        if C is not None:
            cw = C.T @ w
            w -= C @ cw
            CW.append(cw)
        Z.append(z)
        for _ in range(2):
            for i in range(k + 1):
                d = V[i] @ w
                H[i, k] += d
                w -= d * V[i]
        H[k + 1, k] = np.linalg.norm(w)
        V.append(w / H[k + 1, k])
        k += 1
        y = np.linalg.lstsq(H[:k + 1, :k], g[:k + 1], rcond=None)[0]
        if np.linalg.norm(H[:k + 1, :k] @ y - g[:k + 1]) <= target * nb:
            break
    Zm = np.stack(Z, axis=1)
    x += Zm @ y
    if C is not None:
        x -= U @ (np.stack(CW, axis=1) @ y)
    return k, x, Zm


class KernelMap:
    """The products of carried directions on a new free set from the old ones: m's kernel (/kappa) cut
    to a (2 rho + 1)^2 window around each point that left F (its column removed) or joined it (the
    product formed there)."""

    def __init__(self, fft, multiplier, scale, rho):
        N = fft.N
        if not 0 <= 2 * rho < N:
            raise ValueError(f"--window {rho}: the window must fit in the {N}-point grid (0 <= rho < N/2)")
        delta = fft.real_array()
        delta[0, 0] = 1.0
        kernel = fft.apply(delta, multiplier, fft.real_array(), scale)
        self.off = np.arange(-rho, rho + 1)
        self.window = kernel[np.ix_(self.off % N, self.off % N)].ravel()     # K(x - x_p), x = x_p + off
        self.N = N

    def points(self, p):
        i, j = divmod(int(p), self.N)
        return np.add.outer((i + self.off) % self.N * self.N, (j + self.off) % self.N).ravel()

    def __call__(self, Z, W, old, new):
        """Whole-grid columns: Z directions (zero off ``old``), W their products on ``old``; returns the
        products of Z restricted to ``new`` (on ``new``) and how many points left and joined."""
        left, joined = np.setdiff1d(old, new), np.setdiff1d(new, old)
        W = W.copy()
        for p in left:
            W[self.points(p), :] -= np.outer(self.window, Z[p, :])
        Zn = Z.copy()
        Zn[left, :] = 0.0
        back = self.window[::-1]                      # K(x_p - y), y = x_p + off
        for p in joined:
            W[p, :] = back @ Zn[self.points(p), :]
        return W[new, :], left.size, joined.size


def bound_rows(n, velocity, sigma0, carries, window=-1, mode="free"):
    """The real solve's result and, per free-set step of its finest grid, a dict: the set's size, the
    target (the relative residual the real step reached), the real and plain iterations and, per K in
    ``carries``, GCRO's iterations (``K<k>``) and true relative residual (``K<k>_residual``); with a
    ``window`` (rho >= 0) the carried products are mapped (KernelMap).  ``changed``: how many points
    left and joined the set since the step before.  ``mode`` contact: the contact-set steps instead
    (exact products only: c's kernel decays as 1/r, no window holds it)."""
    if mode == "contact" and window >= 0:
        raise ValueError("--window: the contact-set steps' operator c has no local kernel")
    fft, L, h, modulus = paper_case.case(n)
    result, steps = record_steps(fft, L, h, modulus, velocity, sigma0, mode)
    rows = []
    if not steps:
        return result, rows
    op, kappa = steps[0]["op"], steps[0]["kappa"]
    edge = edge_of(op) if mode == "contact" else None
    kmap = KernelMap(fft, op.m, 1.0 / kappa, window) if window >= 0 else None
    carried = {k: None for k in carries}        # K -> (Z whole-grid columns, their products or None, F)
    for s, st in enumerate(steps):
        system = FreeSystem(fft, st) if mode == "free" else ContactSystem(fft, st, edge)
        b = st["b"]
        target = np.linalg.norm(b - system.A(st["y"])) / np.linalg.norm(b)
        row = dict(step=s, set=int(st["idx"].size), target=target, real=st["its"], plain=gcro(system, b, target)[0])
        if s > 0:
            old = steps[s - 1]["idx"]
            row["changed"] = [np.setdiff1d(old, st["idx"]).size, np.setdiff1d(st["idx"], old).size]
        for k in carries:
            U = C = None
            if carried[k] is not None:
                Z, W, old = carried[k]
                U = Z[st["idx"], :]
                if mode == "contact":
                    U = U - U.mean(axis=0)             # zero sum on the new C, as the Krylov vectors
                if kmap is None:
                    AU = np.stack([system.A(u) for u in U.T], axis=1)
                else:
                    AU = kmap(Z, W, old, st["idx"])[0]
                C, R = np.linalg.qr(AU)
                keep = np.abs(np.diag(R)) > 1e-12 * np.abs(np.diag(R)).max()     # dependent columns out
                U, C, R = U[:, keep], C[:, keep], R[np.ix_(keep, keep)]
                U = np.linalg.solve(R.T, U.T).T        # A U R^-1 = C
            its, x, own = gcro(system, b, target, U, C)
            row[f"K{k}"] = its
            row[f"K{k}_residual"] = np.linalg.norm(b - system.A(x)) / np.linalg.norm(b)
            keep = own if U is None else np.concatenate([own, carried[k][0][st["idx"], :]], axis=1)
            keep = keep[:, :k]
            Z = np.zeros((n * n, keep.shape[1]))
            Z[st["idx"], :] = keep
            W = None
            if kmap is not None:                       # what the map starts from (a solver has these)
                W = np.zeros_like(Z)
                W[st["idx"], :] = np.stack([system.A(z) for z in keep.T], axis=1)
            carried[k] = (Z, W, st["idx"])
        rows.append(row)
    return result, rows


def bound(args):
    carries = [int(k) for k in args.carry.split(",")]
    result, rows = bound_rows(args.n, args.velocity, args.sigma0, carries, args.window, args.mode)
    print(f"N {args.n}, {args.velocity} m/s, sigma0 {args.sigma0} Pa: A/A0 {result.area:.4f}, "
          f"{result.fft_pairs:.1f} pairs, {len(rows)} {args.mode}-set steps on the fine grid")
    for row in rows:
        print(json.dumps({k: float(f"{v:.3g}") if isinstance(v, float) else v for k, v in row.items()}))
    keys = ["real", "plain"] + [f"K{k}" for k in carries]
    print("total", json.dumps({k: sum(row[k] for row in rows) for k in keys}))
    return 0 if rows else 1


def pass_cost(args):
    from mpi4py import MPI
    from vecontact.core.pfft import SlabFFT
    comm = MPI.COMM_WORLD
    out = {}
    for precision in ("double", "single"):
        fft = SlabFFT(comm, args.n, planner="measure", precision=precision)
        x = fft.real_array()
        x[...] = np.random.default_rng(comm.rank).standard_normal(x.shape)
        y = fft.real_array()
        ones = np.ones(fft.local_fourier_shape, dtype=fft.complex_dtype)
        out[f"pair_{precision}"] = _median_ms(comm, lambda: fft.apply(x, ones, y))
    n = int(args.fraction * args.n * args.n / comm.size)
    rng = np.random.default_rng(1)
    w = rng.standard_normal(n).astype(np.float32)
    for k in (10, 30, 60):
        V = (rng.standard_normal((k, n)) / math.sqrt(n)).astype(np.float32)

        def project():
            h = comm.allreduce((V @ w).astype(np.float64))
            w[...] -= (1e-9 * h).astype(np.float32) @ V     # scaled: the vector stays finite
        out[f"K{k}"] = _median_ms(comm, project)
    if comm.rank == 0:
        print(json.dumps(dict(N=args.n, ranks=comm.size, fraction=args.fraction,
                              ms={key: round(v, 2) for key, v in out.items()})))
    return 0


def map_cost(args):
    from mpi4py import MPI
    from vecontact.solver.operator import ContactOperator
    from vecontact.solver.recycle import CarriedSpace, ComplianceKernel
    from vecontact.solver.settings import SolverSettings
    comm = MPI.COMM_WORLD
    fft, L, h, modulus = paper_case.case(args.n, comm=comm, planner="measure")
    x, y = fft.real_array(), fft.real_array()
    ones = np.ones(fft.local_fourier_shape, dtype=fft.complex_dtype)
    pair = _median_ms(comm, lambda: fft.apply(x, ones, y))
    kernel = ComplianceKernel(ContactOperator(fft, L, modulus, 10.0, 1e5, h))     # the compliance at 10 m/s
    k = SolverSettings().carry_directions
    rng = np.random.default_rng(4)                  # the same sets on every rank
    N2 = args.n * args.n
    old_set = rng.random(N2) < args.fraction
    lo, hi = fft.row_start * args.n, fft.row_stop * args.n
    old = np.flatnonzero(old_set[lo:hi])
    U = rng.standard_normal((k, old.size)).astype(np.float32)
    space = CarriedSpace(old, U, U.copy())
    rows = []
    for changed in (int(c) for c in args.changed.split(",")):
        new_set = old_set.copy()
        new_set[rng.choice(np.flatnonzero(old_set), changed // 2, replace=False)] = False
        new_set[rng.choice(np.flatnonzero(~old_set), changed - changed // 2, replace=False)] = True
        new = np.flatnonzero(new_set[lo:hi])
        n_new = int(new_set.sum())
        ones_product = np.ones(new.size)
        ms = _median_ms(comm, lambda: space.mapped(fft, new, n_new, kernel, ones_product), repeats=5)
        units = n_new * changed / N2
        rows.append({key: float(f"{v:.4g}") for key, v in
                     dict(units=units, map_ms=ms, pairs=ms / pair, pairs_per_unit=ms / pair / units).items()})
        rows[-1]["changed"] = changed
    if comm.rank == 0:
        print(json.dumps(dict(N=args.n, ranks=comm.size, fraction=args.fraction, K=k, pair_ms=float(f"{pair:.4g}"),
                              rows=rows)))
    return 0


def _median_ms(comm, f, repeats=20):
    for _ in range(3):
        f()
    t = []
    for _ in range(repeats):
        comm.Barrier()
        t0 = time.perf_counter()
        f()
        t.append(time.perf_counter() - t0)
    return float(np.median(t)) * 1e3


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--n", type=int, default=1024)
    p.add_argument("--velocity", type=float, default=0.01, help="m/s")
    p.add_argument("--sigma0", type=float, default=153648.9, help="Pa (the benchmark's 57 %% case at 1024^2)")
    p.add_argument("--carry", default="10,30", help="numbers of carried directions K, comma-separated")
    p.add_argument("--window", type=int, default=-1, help="rho of the kernel map (default: exact products)")
    p.add_argument("--mode", choices=("free", "contact"), default="free", help="which Newton steps")
    p.add_argument("--pass-cost", action="store_true")
    p.add_argument("--fraction", type=float, default=0.43,
                   help="--pass-cost: the free set's share of the grid; --map-cost: the contact set's")
    p.add_argument("--map-cost", action="store_true")
    p.add_argument("--changed", default="10,100,1000", help="--map-cost: points changed, comma-separated")
    args = p.parse_args(argv)
    if args.map_cost:
        return map_cost(args)
    return pass_cost(args) if args.pass_cost else bound(args)


if __name__ == "__main__":
    sys.exit(main())
