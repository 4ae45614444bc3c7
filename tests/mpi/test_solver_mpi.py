"""Collective validation of the contact solver: run as ``mpiexec -n 2 python -m pytest tests/mpi``.

Every rank holds the full reference (cheap at these sizes) and its rows of the problem; results are
gathered and compared on every rank, and the scalars must be identical on all ranks.
Tolerances as in tests/test_solver_dense.py and tests/test_solver_analytic.py (justified there).
"""
import math

import numpy as np
import pytest

from reference import analytic as an
from reference.cases import (CARRY_OPEN, L_PAPER, NU, Q0, assert_contact_solution, make_fft, small_spectrum,
                             solve_full)
from reference.dense import dense_solve, dense_solve_1d, random_surface

from vecontact.physics.modulus import Elastic, HavriliakNegami


def hn():
    return HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10, NU)


def same_on_all_ranks(comm, res):
    vals = np.array([res.area, res.mu, res.mu_geometric, res.mean_gap, float(res.converged), res.residual])
    allv = comm.allgather(vals)
    assert all(np.array_equal(vals, a) for a in allv), allv


def on_all_ranks_and_one(comm, h, mod, v, sigma0, **kw):
    """solve_full on ``comm`` (keywords ``kw`` passed on), guarded by faulthandler (a hang fails the
    stage after 120 s), checked the same on every rank, then on one rank: ((res, fields) on comm,
    (res, fields) on one)."""
    import faulthandler
    from mpi4py import MPI
    faulthandler.dump_traceback_later(120, exit=True)
    try:
        two = solve_full(h, L_PAPER, mod, v, sigma0, comm=comm, **kw)
    finally:
        faulthandler.cancel_dump_traceback_later()
    same_on_all_ranks(comm, two[0])
    return two, solve_full(h, L_PAPER, mod, v, sigma0, comm=MPI.COMM_SELF, **kw)


@pytest.mark.parametrize("N,name,v,sigma0", [(24, "hn", 30.0, 1e5), (32, "hn", 1.0, 2e4), (32, "elastic", 0.0, 5e3)])
def test_dense_collective(comm, N, name, v, sigma0):
    h = random_surface(N, L_PAPER, small_spectrum(N), seed=N)
    mod = hn() if name == "hn" else Elastic(3e6, NU)
    ref = dense_solve(h, L_PAPER, mod, v, sigma0)
    assert 0.05 < ref.area < 0.6 and ref.n_degenerate == 0
    methods = ["snes", "pk"] if name == "elastic" else ["snes"]
    for method in methods:
        res, f = solve_full(h, L_PAPER, mod, v, sigma0, comm=comm, method=method)
        same_on_all_ranks(comm, res)
        assert_contact_solution(res, f, h, sigma0)
        hrms = float(np.std(h))
        assert abs(res.area - ref.area) * N * N <= 1, (method, res.area, ref.area)
        assert np.abs(f["pressure"] - ref.pressure).max() <= 1e-6 * sigma0
        assert np.abs(f["gap"] - ref.gap).max() <= 1e-6 * hrms
        assert abs(res.mean_gap - ref.mean_gap) <= 1e-6 * hrms
        if name == "hn":
            assert abs(res.mu / ref.mu - 1) <= 1e-5, (res.mu, ref.mu)
            assert abs(res.mu_geometric / ref.mu_geometric - 1) <= 1e-5, (res.mu_geometric, ref.mu_geometric)


@pytest.mark.parametrize("method", ["snes", "pk"])
def test_westergaard_collective(comm, method):
    N, D = 128, 1e-8
    x = np.arange(N) * L_PAPER / N
    hx = D * np.cos(2 * math.pi * x / L_PAPER)
    h = hx[:, None] * np.ones((1, N))
    ps = an.westergaard_pstar(3e6, NU, D, L_PAPER)
    r = 0.3
    ref = dense_solve_1d(hx, L_PAPER, Elastic(3e6, NU), 0.0, r * ps)
    res, f = solve_full(h, L_PAPER, Elastic(3e6, NU), 0.0, r * ps, comm=comm, method=method)
    same_on_all_ranks(comm, res)
    assert_contact_solution(res, f, h, r * ps)
    assert abs(res.area - an.westergaard_area(r)) <= 2.0 / N
    assert res.area == ref.area
    assert np.abs(f["pressure"] - ref.pressure[:, None]).max() <= 1e-6 * r * ps
    assert abs(res.mean_gap / an.westergaard_mean_gap(D, r) - 1) <= 1e-3


def test_full_contact_cosine_collective(comm):
    N, h0, m, v = 32, 1e-8, 3, 36.0
    k = 2 * math.pi * m / L_PAPER
    x = np.arange(N) * L_PAPER / N
    h = h0 * np.cos(k * x)[:, None] * np.ones((1, N))
    mod = hn()
    Ek = complex(mod(np.array([k * v]))[0])
    sigma0 = 2 * k * abs(Ek) / (2 * (1 - NU ** 2)) * h0
    res, f = solve_full(h, L_PAPER, mod, v, sigma0, comm=comm)
    same_on_all_ranks(comm, res)
    assert res.area == 1.0
    mu = an.cosine_mu(k, h0, mod, NU, v, sigma0)
    assert abs(res.mu / mu - 1) <= 1e-6 and abs(res.mu_geometric / mu - 1) <= 1e-6
    P = np.fft.fft2(f["pressure"]) / N ** 2
    assert abs(np.angle(P[m, 0]) - an.cosine_phase(k, mod, v)) <= 1e-6


def test_iterate_cache_decided_by_all_ranks_collective(comm):
    """NewtonState.ensure recomputes the pressure (an FFT pair, collective) on every rank when the
    iterate changed on any rank, also on a rank whose own rows did not change; the pressure here is a
    stand-in that only counts its calls, so that the old local decision fails instead of hanging."""
    from vecontact.solver.newton import NewtonState

    class Counting:
        def __init__(self, fft):
            self.fft, self.N, self.kappa, self.calls = fft, fft.N, 1.0, 0

        def pressure(self, g, out):
            self.calls += 1
            np.multiply(g, 2.0, out=out)

    fft = make_fft(comm, 16)
    op = Counting(fft)
    st = NewtonState(op)
    g = np.ones(fft.local_real_shape)
    st.ensure(g)
    st.ensure(g.copy())                      # the same everywhere: no new pair
    if comm.rank == 0:
        g[0, 0] = 3.0                        # a change on one rank only
    st.ensure(g)
    assert comm.allgather(op.calls) == [2] * comm.size
    assert np.array_equal(st.p, 2.0 * g)


def test_a_step_that_leaves_a_rank_unchanged_collective(comm):
    """A sharp rubber (HN alpha = beta = 0.8) at 1 mm/s pressed to 99.9 % contact on a 64^2 grid: one
    Newton step changes the iterate on one rank's rows only. Before the cache's decision was
    collective the other rank skipped the pressure's FFT pair and both waited for ever (guarded here by
    faulthandler: a hang fails the stage after 120 s); now the solve matches the one-rank solve (the
    same Newton iterations and contact area, pressure to 1e-9 of sigma0)."""
    N, sigma0 = 64, 2e5
    h = random_surface(N, L_PAPER, small_spectrum(N), seed=4)
    mod = HavriliakNegami(3e6, 3e9, 0.8, 0.8, 1e-6, NU)
    (two, f2), (one, f1) = on_all_ranks_and_one(comm, h, mod, 0.001, sigma0)
    assert two.converged and one.converged and 0.99 < two.area < 1.0
    assert two.iterations == one.iterations and two.area == one.area
    assert np.abs(f2["pressure"] - f1["pressure"]).max() <= 1e-9 * sigma0


def test_stall_retry_collective(comm):
    """The stall rules decide on every rank alike (global iteration counts, the global measure): the
    sharp rubber at 1 cm/s on the tests' 128^2 surface, 4 % in contact, on 2 ranks and on 1. Its 64^2
    grid stalls with the edge term and starts again without it, the 128^2 grid then runs without it;
    the stalled attempts' paths depend on the transforms' rounding, the answers do not: the same
    contact set, the pressure to 1e-6 of sigma0 (both meet the measures' 1e-8; measured 1.1e-8)."""
    from mpi4py import MPI
    N, sigma0 = 128, 3e4
    h = random_surface(N, L_PAPER, small_spectrum(N), seed=4)
    mod = HavriliakNegami(3e6, 3e9, 0.8, 0.8, 1e-6, NU)
    two, f2 = solve_full(h, L_PAPER, mod, 0.01, sigma0, comm=comm, store=("pressure",))
    one, f1 = solve_full(h, L_PAPER, mod, 0.01, sigma0, comm=MPI.COMM_SELF, store=("pressure",))
    same_on_all_ranks(comm, two)
    for r in (two, one):
        coarse, fine = r.diagnostics["levels"]
        assert r.converged and coarse["edge_retry"] is not None and fine["edge_retry"] is None
    assert two.area == one.area
    assert np.abs(f2["pressure"] - f1["pressure"]).max() <= 1e-6 * sigma0


@pytest.mark.parametrize("fallback", ["bt", "vi"])
def test_fallback_collective(comm, fallback):
    """The fallback after full steps stop gaining (fallback_stall, then the line search or the VI
    method) decides on every rank alike (the global measure) and builds its SNES collectively (the VI
    method's sub-matrices too): the SLS rubber at 1 mm/s on the tests' 64^2 surface, 18 % in contact
    (tests/test_solver_fallback.py), on 2 ranks guarded by faulthandler (a hang fails the stage after
    120 s), and on 1. Both take the fallback; their paths depend on the transforms' rounding, their
    answers do not: the same contact set, the pressure to 1e-6 of sigma0 (both meet the measures' 1e-8;
    measured 1.1e-8 on 2 ranks, 5e-9 on 3, with bt), each a contact solution on its fields."""
    from vecontact.physics.modulus import SLS
    N = 64
    h = random_surface(N, L_PAPER, small_spectrum(N), seed=4)
    mod = SLS(3e6, 3e8, 1e-5, NU)
    sigma0 = 1e-3 * abs(complex(mod(np.array([2 * np.pi / L_PAPER * 8 * 0.001]))[0]))
    (two, f2), (one, f1) = on_all_ranks_and_one(comm, h, mod, 0.001, sigma0,
                                                petsc_options=["-vc_fallback", fallback])
    for r, f in ((two, f2), (one, f1)):
        assert r.converged and r.diagnostics["fallback_retry"] is not None
        assert_contact_solution(r, f, h, sigma0)
    assert two.area == one.area
    assert np.abs(f2["pressure"] - f1["pressure"]).max() <= 1e-6 * sigma0


def test_coarse_fallback_collective(comm):
    """A coarse grid whose full steps fail takes the fallback, and the finer grid starts with it
    (fallback_coarse; tests/test_solver_fallback.py): the SLS rubber at 1 mm/s on the paper's 256^2
    surface, 0.24 % in contact, on 2 ranks guarded by faulthandler and on 1. Both decide alike on
    every rank: 128^2 takes the fallback, 256^2 starts with it; the same contact set, the pressure
    to 1e-6 of sigma0, each a contact solution on its fields."""
    from reference.cases import paper_case
    from vecontact.physics.modulus import SLS
    _, h, _ = paper_case(256)
    mod = SLS(3e6, 3e8, 1e-5, NU)
    sigma0 = 1e-4 * abs(complex(mod(np.array([8 * Q0 * 0.001]))[0]))
    (two, f2), (one, f1) = on_all_ranks_and_one(comm, h, mod, 0.001, sigma0)
    for r, f in ((two, f2), (one, f1)):
        levels = r.diagnostics["levels"]
        assert r.converged and [lv["N"] for lv in levels] == [64, 128, 256]
        assert levels[1]["fallback_retry"] is not None and levels[2]["fallback_direct"]
        assert_contact_solution(r, f, h, sigma0)
    assert two.area == one.area
    assert np.abs(f2["pressure"] - f1["pressure"]).max() <= 1e-6 * sigma0


@pytest.mark.slow
def test_mu_vs_mu_geometric_paper_512_collective(comm):
    """Paper's smallest case (q1 = 32 q0, N = 512, null band 8) on 2 ranks: mu_geometric = mu within 2%."""
    from vecontact.core.surface import generate
    from vecontact.physics.spectrum import SelfAffine
    N = 512
    fft = make_fft(comm, N)
    psd = SelfAffine(Q0, 4 * Q0, 32 * Q0, 0.8, 1.0616e-28)
    h_local = generate(fft, L_PAPER, psd, 1)
    from vecontact.solver import solve_contact
    res = solve_contact(fft, L_PAPER, h_local, hn(), 1.0, 1e4)   # A/A0 = 1.2%
    same_on_all_ranks(comm, res)
    assert res.converged
    assert res.area >= 0.01 and res.mu > 1e-3, (res.area, res.mu)
    assert abs(res.mu_geometric / res.mu - 1) <= 0.02, (res.area, res.mu, res.mu_geometric)


def test_solver_state_is_freed_collective(comm):
    """After a solve on 2 ranks no solver state survives: petsc4py defers the destruction of collected
    objects on parallel communicators, and a deferred PC keeps its Python context (the whole solve's
    N^2 arrays) alive; a 4096^2 sweep grew by 0.9 GB per case and rank before this was cleaned up.
    The automatic collector is off during the solve and the test collects nothing: the solve itself
    (its dropped references, and its own collection, which walks only what it made) must free them."""
    import gc
    from vecontact.solver.contactset import ContactSetStep
    from vecontact.solver.freeset import FreeSetStep
    from vecontact.solver.measurestop import MeasureStop
    from vecontact.solver.newton import NewtonState
    from vecontact.solver.snes import _Semismooth
    N = 48
    h = random_surface(N, L_PAPER, small_spectrum(N), seed=3)
    for step in ("contact", "free"):
        gc.disable()
        try:
            res, _ = solve_full(h, L_PAPER, hn(), 1.0, 2e4, comm=comm,
                                petsc_options={"vc_contact_step": step})
        finally:
            gc.enable()
        assert res.converged
        kinds = (ContactSetStep, FreeSetStep, NewtonState, _Semismooth, MeasureStop)
        alive = [type(o).__name__ for o in gc.get_objects() if isinstance(o, kinds)]
        assert alive == [], (step, alive)


@pytest.mark.parametrize("N, v, sigma0", [(256, 10.0, 1e6), (512, 0.01, 3.5e4)])
def test_measure_stop_collective(comm, N, v, sigma0):
    """The measure stop of exact steps (measurestop.py) on 2 ranks, on the free set (256^2, A/A0 ~ 0.58)
    and on the contact set (512^2, ~ 0.21; at 4e4 and 5e4 the edge-corrected steps converge before an
    exact step looks, and so does an exact step started from the carried directions: carry.py off here): its
    looks are collective (a trial iterate's pressure and
    measure, the vectors of the step's current set) and give the same stop on every rank; the answer
    is one rank's to the solver's tolerance (A/A0 to a few contact-line points, mu to 1e-6)."""
    from vecontact.core.pfft import SlabFFT
    from vecontact.core.surface import generate
    from vecontact.physics.spectrum import SelfAffine
    from vecontact.solver import solve_contact
    tol = 1e-8
    psd = SelfAffine(Q0, 4 * Q0, N // 16 * Q0, 0.8, 1.0616e-28)
    out = []
    for c in (comm, comm.Split(comm.rank, 0)):
        fft = SlabFFT(c, N, planner="estimate", wisdom_file=False)
        h = generate(fft, L_PAPER, psd, 1)
        out.append(solve_contact(fft, L_PAPER, h, hn(), v, sigma0, tolerance=tol, store=(),
                                 petsc_options={"vc_carry_directions": "0"}))
    res, one = out
    same_on_all_ranks(comm, res)
    looks = res.diagnostics["measure_checks"]
    assert comm.allgather(looks) == [looks] * comm.size
    assert res.converged and one.converged and looks and looks[-1][2] <= tol, looks
    assert res.residual == pytest.approx(looks[-1][2], rel=1e-9)
    assert abs(res.area - one.area) * N * N <= 4 and abs(res.mu / one.mu - 1) <= 1e-6, (res.summary(), one.summary())


def test_measure_stop_follows_the_step_vectors_collective(comm):
    """A look builds the update into a copy of the step's inner vector; when the next contact set
    changes one rank's share only, the step remakes its vectors (collectively, subset.py) and the stop
    must follow on every rank (a test of the local size once left the other rank waiting: deadlock).
    With tol 1e30 every armed solve stops at its first look, after one iteration."""
    from vecontact.solver.contactset import ContactSetStep
    from vecontact.solver.measurestop import MeasureStop
    from vecontact.solver.newton import NewtonState
    from vecontact.solver.operator import ContactOperator
    from vecontact.solver.settings import SolverSettings
    from vecontact.solver.snes import hold_comm, petsc
    PETSc = petsc()
    N = 32
    fft = make_fft(comm, N)
    hold_comm(comm)
    h = random_surface(N, L_PAPER, small_spectrum(N), seed=4)
    rows = slice(fft.row_start, fft.row_stop)
    op = ContactOperator(fft, L_PAPER, hn(), 1.0, 2e4, np.ascontiguousarray(h[rows]))
    state = NewtonState(op)
    state.ensure(-op.hhat)
    high = h > np.quantile(h, 0.8)
    first_rows = np.arange(N)[:, None] < N // 4 + np.zeros((1, N))     # rank 0's rows on 2 ranks
    sets = (high, high | (first_rows & (h > np.quantile(h, 0.6))))
    step = ContactSetStep(op, op.kappa, PETSc, "mstest_", SolverSettings())
    stop = MeasureStop(state, 1e30, PETSc)
    stop.attach(step)
    r = PETSc.Vec().createMPI((h[rows].size, N * N), comm=comm)
    x = r.duplicate()
    try:
        r.getArray()[:] = np.random.default_rng(1).standard_normal((N, N))[rows].ravel()
        for k, act in enumerate(sets):
            step.set_active(np.ascontiguousarray(act[rows]), int(np.count_nonzero(act)))
            step.set_tolerances(1e-12, 0.0, 50)
            stop.arm(1.0)
            step.apply(None, r, x)
            assert step.ksp.getConvergedReason() == PETSc.KSP.ConvergedReason.CONVERGED_USER
            assert len(stop.trace) == k + 1 and stop.trace[-1][0] == 1, stop.trace
    finally:
        stop.release()
        step.release()
        r.destroy()
        x.destroy()


_DOUBLE = {"vc_changing_precision": "double", "vc_cycle_precision": "double", "vc_pc_range_max": "0",
           "vc_single_exact_reduction_max": "0"}
_CYCLES = {"vc_changing_precision": "double", "vc_cycle_precision": "single", "vc_cycle_after_cap": "1",
           "vc_lin_maxit_changing": "10"}       # the first step uses its cap: cycles from the second on


@pytest.mark.parametrize("sigma0, mode, options", [(1.0e6, "free", {"vc_changing_precision": "single"}),
                                                   (1.0e5, "contact", {"vc_changing_precision": "single"}),
                                                   (1.0e6, "free", _CYCLES)])
def test_single_steps_collective(comm, sigma0, mode, options):
    """Single-precision changing steps (single.py), and float32 GMRES cycles under PETSc's FGMRES
    (subset.SingleCycles), on 2 ranks: their float32 pairs run on every rank alike (the GMRES sums are
    float64 and identical on all ranks, so every rank stops at the same iteration), and the answer is
    one rank's in double precision to the solver's tolerance."""
    from vecontact.core.pfft import SlabFFT
    from vecontact.core.surface import generate
    from vecontact.physics.spectrum import SelfAffine
    from vecontact.solver import solve_contact
    N, tol = 256, 1e-8
    psd = SelfAffine(Q0, 4 * Q0, N // 16 * Q0, 0.8, 1.0616e-28)
    out = []
    for c, opts in ((comm, options), (comm.Split(comm.rank, 0), _DOUBLE)):
        fft = SlabFFT(c, N, planner="estimate", wisdom_file=False)
        h = generate(fft, L_PAPER, psd, 1)
        t0 = fft.single_transforms
        r = solve_contact(fft, L_PAPER, h, hn(), 10.0, sigma0, tolerance=tol, store=(), petsc_options=opts)
        out.append((r, (fft.single_transforms - t0) / 2))
    (res, single), (one, none) = out
    same_on_all_ranks(comm, res)
    mine = (single, res.diagnostics["linear_history"])
    assert comm.allgather(mine) == [mine] * comm.size
    assert single > 0.3 * res.fft_pairs and none == 0
    assert res.diagnostics["step_modes"][-1][1] == mode
    assert res.converged and one.converged
    assert abs(res.area - one.area) * N * N <= 4 and abs(res.mu / one.mu - 1) <= 1e-6, (res.summary(), one.summary())


def test_carried_directions_collective(comm):
    """An exact contact-set step started from the last step's directions (carry.py) on 2 ranks: every
    rank carries the same number of them (the count is collective), so the step's Krylov iterations are
    one process; the answer is one rank's without them to the solver's tolerance.  The 256^2 grid's
    modulus range at 10 m/s (82) is under carry_modulus_min's default: opened to 50."""
    from vecontact.core.pfft import SlabFFT
    from vecontact.core.surface import generate
    from vecontact.physics.spectrum import SelfAffine
    from vecontact.solver import solve_contact
    N, tol = 256, 1e-8
    psd = SelfAffine(Q0, 4 * Q0, N // 16 * Q0, 0.8, 1.0616e-28)
    out = []
    for c, opts in ((comm, CARRY_OPEN), (comm.Split(comm.rank, 0), {"vc_carry_directions": "0"})):
        fft = SlabFFT(c, N, planner="estimate", wisdom_file=False)
        h = generate(fft, L_PAPER, psd, 1)
        out.append(solve_contact(fft, L_PAPER, h, hn(), 10.0, 1.0e5, tolerance=tol, store=(), petsc_options=opts))
    res, one = out
    same_on_all_ranks(comm, res)
    mine = (res.diagnostics["carried_directions"], res.diagnostics["linear_history"])
    assert comm.allgather(mine) == [mine] * comm.size
    assert mine[0] > 0 and one.diagnostics["carried_directions"] == 0
    assert res.diagnostics["step_modes"][-1][1] == "contact"
    assert res.converged and one.converged and res.linear_iterations < one.linear_iterations
    assert abs(res.area - one.area) * N * N <= 4 and abs(res.mu / one.mu - 1) <= 1e-6, (res.summary(), one.summary())


def _edge_terms(comm, h, sets, x, w=2, kind="inverse"):
    """The edge term (edge.py, half width ``w``, drop 0.2, rows ``kind``) of ``x`` on the last of ``sets``
    (whole-grid bool arrays, built one after the other by one EdgeCorrection), on ``comm`` and on this
    rank alone: (this rank's term on ``comm``, its rows of the one-rank term, the one-rank term)."""
    from vecontact.core.pfft import SlabFFT
    from vecontact.solver.edge import EdgeCorrection
    from vecontact.solver.operator import ContactOperator
    N = h.shape[0]
    terms, slabs = [], []
    for c in (comm, comm.Split(comm.rank, 0)):
        fft = SlabFFT(c, N, planner="estimate", wisdom_file=False)
        rows = slice(fft.row_start, fft.row_stop)
        slabs.append(rows)
        ec = EdgeCorrection(ContactOperator(fft, L_PAPER, hn(), 1.0, 1e5, h[rows]), w, 0.2, rows=kind)
        for a in sets:
            ec.build(a[rows], np.flatnonzero(a[rows].ravel()))
        idx = np.flatnonzero(sets[-1][rows].ravel())
        terms.append(ec.apply(x[fft.row_start * N:fft.row_stop * N][idx]))
    two, one = terms
    full = np.zeros((N, N))
    full[sets[-1]] = one
    return two, full[slabs[0]][sets[-1][slabs[0]]], one


@pytest.mark.parametrize("where, w, kind", [("patches", 2, "inverse"), ("one slab", 2, "inverse"),
                                            ("patches", 3, "inverse"), ("patches", 1, "schur"),
                                            ("patches", 3, "schur"), ("one slab", 3, "schur")])
def test_edge_term_collective(comm, where, w, kind):
    """The edge correction of the contact-set preconditioner (edge.py) on 2 ranks: the halo rows of the
    contact set and of x come from the neighbouring slabs (and wrap around), so each rank's term is
    its rows of the one-rank term, to FFT rounding of the kernel (rtol 1e-12 of the term's largest
    entry).  "one slab": contact in the first rank's rows only, so the other has no edge point and no
    mask to solve, and must still join the kernel's collective FFT pair (it once waited alone).  Both
    kinds of rows (the compliance's local inverses, the stiffness's Schur complements) and the half
    widths the rules take (1, 2, 3: halos of as many rows)."""
    N = 32
    h = random_surface(N, L_PAPER, small_spectrum(N), seed=9)
    act = h > np.quantile(h, 0.7)
    if where == "one slab":
        act[N // comm.size - 1:] = False
        act[0] = False
    x = np.random.default_rng(3).standard_normal(N * N)
    two, ref, one = _edge_terms(comm, h, [act], x, w, kind)
    if where == "patches":
        assert act[:w].any() and act[-w:].any() and act[N // 2 - w:N // 2 + w].any()     # halos hold contact
    assert np.abs(two - ref).max(initial=0.0) <= 1e-12 * np.abs(one).max() and np.abs(one).max() > 0


def test_edge_term_rebuilt_when_one_rank_changes(comm):
    """A set that changes in one slab only, next to the other: every rank builds again (the halo
    rows changed for the neighbour too; a rank that kept its S would also leave the other waiting in
    the halo exchange), and each rank's term is its rows of the one-rank term (rtol 1e-12)."""
    N = 32
    h = random_surface(N, L_PAPER, small_spectrum(N), seed=9)
    act = h > np.quantile(h, 0.7)
    changed = act.copy()
    last = N // comm.size - 1                           # the first slab's last row, in the 2-rank split
    changed[last, np.flatnonzero(~act[last])[:3]] = True
    x = np.random.default_rng(3).standard_normal(N * N)
    two, ref, one = _edge_terms(comm, h, [act, changed], x)
    assert np.abs(two - ref).max(initial=0.0) <= 1e-12 * np.abs(one).max() and np.abs(one).max() > 0


def test_carried_map_collective(comm):
    """The map of carried directions to a new contact set (recycle.py) on 2 ranks against one: the left
    and joined points of either slab reach the other's kernel columns (and the joined rows' sums span
    both slabs), so each rank's rows match the one-rank map to rounding; the count of changed points
    and the basis's size are the same on every rank."""
    from vecontact.core.pfft import SlabFFT
    from vecontact.solver.operator import ContactOperator
    from vecontact.solver.recycle import CarriedSpace, ComplianceKernel
    N = 24
    h = random_surface(N, L_PAPER, small_spectrum(N), seed=5)
    rng = np.random.default_rng(7)
    old_set = h > np.quantile(h, 0.7)
    new_set = old_set.copy()
    new_set.flat[rng.choice(np.flatnonzero(old_set), 9, replace=False)] = False
    new_set.flat[rng.choice(np.flatnonzero(~old_set), 7, replace=False)] = True
    U_full = rng.standard_normal((4, N, N))
    out = []
    for c in (comm, comm.Split(comm.rank, 0)):
        fft = SlabFFT(c, N, planner="estimate", wisdom_file=False)
        rows = slice(fft.row_start, fft.row_stop)
        op = ContactOperator(fft, L_PAPER, hn(), 1.0, 1e5, h[rows])
        old, new = np.flatnonzero(old_set[rows].ravel()), np.flatnonzero(new_set[rows].ravel())
        U = U_full[:, rows].reshape(4, -1)[:, old]
        U -= (fft._allsum(U.sum(axis=1)) / int(old_set.sum()))[:, None]
        W = np.empty(U.shape, dtype=np.float32)
        buf, prod = fft.real_array(), fft.real_array()
        for u, w in zip(U, W):                    # raw products on the old set, by FFT
            buf[...] = 0.0
            buf.ravel()[old] = u
            fft.apply(buf, op.c, prod)
            w[...] = prod.ravel()[old]
        buf[...] = 0.0
        buf.ravel()[new] = 1.0
        ones_product = fft.apply(buf, op.c, prod).ravel()[new].copy()
        n_new = int(new_set.sum())
        got = CarriedSpace(old, U, W).mapped(fft, new, n_new, ComplianceKernel(op), ones_product)
        full = np.zeros((4, N * N))
        full[:, rows.start * N + new] = got.W          # this rank's rows, placed on the grid
        out.append((full, CarriedSpace.changed(fft, old, new), got.basis(fft, n_new, 1e-8).size, rows))
    (two, changed2, size2, rows), (one, changed1, size1, _) = out
    assert changed2 == changed1 == 16 and size2 == size1 == 4
    assert comm.allgather((changed2, size2)) == [(changed2, size2)] * comm.size
    mine, ref = two[:, rows.start * N:rows.stop * N], one[:, rows.start * N:rows.stop * N]
    assert np.abs(mine - ref).max() <= 1e-6 * np.abs(one).max()


def test_vi_step_sets_its_active_set_on_every_rank(comm):
    """The VI method's step (vi.ViNewton.stiffness_inverse) resets the contact-set step's active set, a
    collective call, whenever the inactive set changed on any rank: here it changes on rank 0 only
    (one point of I joins A), and the step must still match one made afresh for the new set (to 1e-9
    of max|y|: both at rtol 1e-12), under faulthandler (a hang fails the stage after 120 s).  Calling
    set_active only where the local set changed hung the VI fallback on 2 ranks (session 81), and
    hangs this test (tried)."""
    import faulthandler
    from mpi4py import MPI
    from vecontact.solver.contactset import ContactSetStep
    from vecontact.solver.newton import NewtonState
    from vecontact.solver.operator import ContactOperator
    from vecontact.solver.settings import SolverSettings
    from vecontact.solver.snes import petsc
    from vecontact.solver.vi import ViNewton
    PETSc = petsc()
    N = 32
    fft = make_fft(comm, N)
    h = random_surface(N, L_PAPER, small_spectrum(N), seed=N)
    rows = slice(fft.row_start, fft.row_start + fft.local_real_shape[0])
    op = ContactOperator(fft, L_PAPER, hn(), 1.0, 1e4, h[rows])
    settings = SolverSettings(edge_window=0, vi_step_rtol=1e-12)
    free = (h <= np.quantile(h, 0.9))[rows]
    idx0 = np.flatnonzero(free.ravel())
    idx1 = idx0[1:] if comm.rank == 0 else idx0

    def step_of(vi, idx):
        x = PETSc.Vec().createMPI((idx.size, PETSc.DECIDE), comm=comm)
        y = x.duplicate()
        x.getArray()[:] = np.cos(idx)          # the same values on any split of the rows
        assert vi.stiffness_inverse(idx, x, y)
        out = y.getArray(readonly=True).copy()
        x.destroy()
        y.destroy()
        return out

    vis = [ViNewton(NewtonState(op), PETSc, ContactSetStep(op, op.kappa, PETSc, f"vimpi{k}_", settings))
           for k in range(2)]
    faulthandler.dump_traceback_later(120, exit=True)
    try:
        step_of(vis[0], idx0)
        changed_here = step_of(vis[0], idx1)
        fresh = step_of(vis[1], idx1)
    finally:
        faulthandler.cancel_dump_traceback_later()
        for vi in vis:
            vi.release()
    scale = comm.allreduce(float(np.max(np.abs(fresh))), op=MPI.MAX)
    assert comm.allreduce(float(np.max(np.abs(changed_here - fresh))), op=MPI.MAX) <= 1e-9 * scale
