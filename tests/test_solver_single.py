"""Single-precision Newton steps (vecontact/solver/single.py, changing_precision).

* SingleGMRES against a dense solve and against PETSc's KSPGMRES (right preconditioning, the same
  restart): the same stopping test, so the same iteration counts up to float32 rounding of the
  residual estimate, and a true residual that meets the tolerance;
* the solver with single-precision changing steps against double precision on paper surfaces at
  10 m/s (free-set and contact-set steps): the same answer to the solver's tolerance, and the float32
  pairs really ran (and only while the policy allows them);
* the float32 GMRES cycles under PETSc's FGMRES (cycle_precision) against PETSc's own cycles;
* float32 pairs in the preconditioners of FGMRES (pc_range_max) against float64 ones.
"""
import numpy as np
import pytest

from reference.cases import CARRY_OPEN, L_PAPER, paper_case
from reference.krylov import allsum as _allsum, operators as _ops, system as _system

from vecontact.solver import solve_contact
from vecontact.solver.single import SingleGMRES


@pytest.mark.parametrize("restart, work", [(200, np.float32), (15, np.float32), (15, np.float64)])
def test_single_gmres_against_dense(restart, work):
    A, B, b = _system()
    opA, opB = _ops(A, B)
    x = np.empty_like(b)
    gm = SingleGMRES(b.size, restart, _allsum, work=work)
    for rtol in (1e-2, 1e-4):
        its, est = gm.solve(opA, opB, b, x, rtol, 0.0, 500)
        true = np.linalg.norm(b - A @ x)
        nb = np.linalg.norm(b)
        # the estimate is the float64 Givens residual of a float32 Arnoldi process: it tracks the
        # true residual to float32 rounding of the products (~1e-6 |b| here)
        assert est <= rtol * nb and 1 < its < 500
        assert true <= rtol * nb * 1.05 + 2e-6 * nb, (rtol, its, est, true)
        assert abs(true - est) <= 2e-6 * nb + 0.05 * est
    # a solution that really is the solve's: it approaches the dense one
    xd = np.linalg.solve(A, b)
    assert np.linalg.norm(x - xd) <= 1e-2 * np.linalg.norm(xd)


def test_single_gmres_iterations_as_petsc():
    """Same stopping rule as KSPGMRES with right preconditioning (PETSc's default test from x0 = 0)."""
    from petsc4py import PETSc
    A, B, b = _system(seed=5)
    n = b.size
    for restart, rtol in ((200, 1e-3), (12, 1e-3)):
        gm = SingleGMRES(n, restart, _allsum)
        x = np.empty_like(b)
        its, _ = gm.solve(*_ops(A, B), b, x, rtol, 0.0, 1000)
        mat = PETSc.Mat().createDense((n, n), array=A.copy(), comm=PETSc.COMM_SELF)
        pmat = PETSc.Mat().createDense((n, n), array=B.copy(), comm=PETSc.COMM_SELF)
        ksp = PETSc.KSP().create(comm=PETSc.COMM_SELF)
        ksp.setOperators(mat)
        ksp.setType("gmres")
        ksp.setGMRESRestart(restart)
        ksp.setPCSide(PETSc.PC.Side.RIGHT)
        pc = ksp.getPC()
        pc.setType("mat")
        pc.setOperators(mat, pmat)
        ksp.setTolerances(rtol=rtol, atol=0.0, max_it=1000)
        bv = PETSc.Vec().createWithArray(b.copy(), comm=PETSc.COMM_SELF)
        xv = bv.duplicate()
        ksp.solve(bv, xv)
        assert ksp.getConvergedReason() > 0
        assert abs(its - ksp.getIterationNumber()) <= 1, (restart, its, ksp.getIterationNumber())
        assert np.linalg.norm(x - xv.getArray()) <= 10 * rtol * np.linalg.norm(xv.getArray())
        for o in (ksp, mat, pmat, bv, xv):
            o.destroy()


def test_single_gmres_caps_and_trivial_cases():
    A, B, b = _system()
    opA, opB = _ops(A, B)
    x = np.empty_like(b)
    gm = SingleGMRES(b.size, 30, _allsum)
    its, est = gm.solve(opA, opB, b, x, 1e-12, 0.0, 7)            # the cap
    assert its == 7 and len(gm.history) == 8 and est == gm.history[-1] > 0
    its, est = gm.solve(opA, opB, b, x, 0.5, 1e30, 50)            # atol met at once: still 1 (min_it)
    assert its == 1 and np.all(np.isfinite(x)) and np.any(x != 0)
    its, est = gm.solve(opA, opB, np.zeros_like(b), x, 0.1, 0.0, 50)
    assert its == 0 and est == 0.0 and not np.any(x)


def test_single_gmres_flexible_same_iterations():
    """Keeping B v_k (flexible) changes where the solution is formed, not the iterations."""
    A, B, b = _system(seed=7)
    res = []
    for flexible in (False, True):
        x = np.empty_like(b)
        its, _ = SingleGMRES(b.size, 20, _allsum, flexible=flexible, work=np.float64).solve(
            *_ops(A, B), b, x, 1e-4, 0.0, 300)
        res.append((its, x))
    assert res[0][0] == res[1][0]
    assert np.linalg.norm(res[0][1] - res[1][1]) <= 1e-4 * np.linalg.norm(res[0][1])


@pytest.mark.parametrize("restart", [200, 8])
def test_single_gmres_monitor_builds_the_solution_it_stops_at(restart):
    """The monitor (the measure stop of exact steps, measurestop.py) sees the start and every later
    iteration; the trial solution it builds after 12 iterations is, bit for bit, what the solve returns
    when stopped there, and what a solve capped at 12 iterations returns (restart 8: across a
    restart, whose residual and solution carry over).  Bit-identity is the contract: the measure stop
    keeps the trial iterate as the Newton iterate the solve's answer makes."""
    A, B, b = _system(seed=7)
    ref = np.empty_like(b)
    its_ref, _ = SingleGMRES(b.size, restart, _allsum, flexible=True, work=np.float64).solve(
        *_ops(A, B), b, ref, 1e-12, 0.0, 12)
    seen, trials = [], []

    def monitor(its, res, build):
        seen.append((its, build is None))
        if its == 12:
            trials.append(np.full_like(b, np.nan))
            build(trials[-1])
            return True
        return False
    x = np.empty_like(b)
    its, _ = SingleGMRES(b.size, restart, _allsum, flexible=True, work=np.float64).solve(
        *_ops(A, B), b, x, 1e-12, 0.0, 300, monitor=monitor)
    assert its == its_ref == 12
    assert seen == [(0, True)] + [(k, False) for k in range(1, 13)]
    assert np.array_equal(trials[0], x) and np.array_equal(x, ref)
    assert np.linalg.norm(b - A @ x) < 0.5 * np.linalg.norm(b)         # a real partial solve
    with pytest.raises(ValueError, match="flexible"):
        SingleGMRES(b.size, restart, _allsum).solve(*_ops(A, B), b, x, 1e-12, 0.0, 300, monitor=monitor)


def test_single_gmres_restarts_a_stalled_cycle():
    """``stall``: a cycle whose estimate is below the reduction and fell by less than half over the
    window restarts from the true residual.  On the dense system below a float32 basis loses its
    orthogonality near 2e-5 of |b|: without the rule the estimate crawls on while the true residual
    stands still, and a solve to 1e-5 returns a residual 4.6 times its tolerance (a solve to 1e-6
    learns it only at the restart after 200 iterations); with it both meet their tolerance by the true
    residual, the second in about half the iterations.  A solve that never stalls (to 1e-4) is
    untouched, bit for bit."""
    A, B, b = _system(seed=7)
    nb = np.linalg.norm(b)

    def solve(rtol, stall):
        x = np.empty_like(b)
        gm = SingleGMRES(b.size, 200, _allsum, flexible=True, work=np.float64)
        its, est = gm.solve(*_ops(A, B), b, x, rtol, 0.0, 400, stall=stall)
        return its, x, gm.stalls, np.linalg.norm(b - A @ x)

    rule = (1e-4, 10)
    plain, ruled = solve(1e-4, None), solve(1e-4, rule)
    assert ruled[2] == 0 and plain[0] == ruled[0] and np.array_equal(plain[1], ruled[1])
    assert solve(1e-5, None)[3] > 2 * 1e-5 * nb                        # the estimate lied
    for rtol in (1e-5, 1e-6):
        its, _, stalls, true = solve(rtol, rule)
        assert stalls >= 1 and true <= 1.05 * rtol * nb, (rtol, its, stalls, true / nb)
    assert solve(1e-6, rule)[0] < 0.7 * solve(1e-6, None)[0]
    # a genuine plateau (a cyclic shift: the estimate stands at |b| until the n-th iteration) restarts
    # after every window + 1 iterations, from b - A x
    n = 40
    shift = np.roll(np.eye(n), 1, axis=0)
    e0 = np.zeros(n)
    e0[0] = 1.0
    for window in (3, 5):
        gm = SingleGMRES(n, 30, _allsum, flexible=True, work=np.float64)
        x = np.empty(n)
        its, est = gm.solve(*_ops(shift, np.eye(n)), e0, x, 1e-6, 0.0, 24, stall=(1.0, window))
        assert its == 24 and gm.stalls == 24 // (window + 1) - (24 % (window + 1) == 0)
        assert est == pytest.approx(np.linalg.norm(e0 - shift @ x), rel=1e-12)


def test_single_gmres_without_preconditioner_skips_only_a_copy():
    """``B`` None (the GMRES cycles): the basis vector goes to A as it is.  That only drops the copy an
    identity preconditioner makes, so iterations, residual estimates and solution are the same bit for
    bit (the contract: a copy does not round)."""
    A, _, b = _system(seed=5)
    opA, _ = _ops(A, A)
    runs = []
    for B in (lambda v, out: np.copyto(out, v, casting="same_kind"), None):
        for restart in (12, 200):                                  # with and without restarts
            gm = SingleGMRES(b.size, restart, _allsum)
            x = np.empty_like(b)
            its, est = gm.solve(opA, B, b, x, 1e-3, 0.0, 400)
            runs.append((its, list(gm.history), x))
    for (i1, h1, x1), (i2, h2, x2) in zip(runs[:2], runs[2:]):
        assert i1 == i2 > 20 and h1 == h2 and np.array_equal(x1, x2)
    # a true solve: unpreconditioned, the float32 products err by ~cond(A) x 6e-8 x sqrt(n) ~ 1e-4 of |b|
    assert np.linalg.norm(b - A @ runs[3][2]) <= (1.05e-3 + 1e-4) * np.linalg.norm(b)


def test_single_gmres_rescales_its_rows_exactly(monkeypatch):
    """The basis rows are kept unnormalised (row i = s_i v_i) and multiplied by a power of two when
    their scale leaves [2^-_RANGE, 2^_RANGE].  Such a product rounds nothing, so rescaling at nearly
    every iteration (_RANGE 2) gives the same iterations, residual estimates and solution, bit for bit,
    as never rescaling (_RANGE 120: unpreconditioned, this operator's rows grow by up to 2^7 an
    iteration, so restarts every 4 keep them inside float32's range)."""
    import vecontact.solver.single as single
    A, _, b = _system(seed=11)
    opA, _ = _ops(A, A)
    runs = []
    for rng_ in (2, 120):
        monkeypatch.setattr(single, "_RANGE", rng_)
        gm = SingleGMRES(b.size, 4, _allsum)
        x = np.empty_like(b)
        its, _ = gm.solve(opA, None, b, x, 1e-3, 0.0, 40)
        runs.append((its, list(gm.history), x, gm.rescales))
    (i1, h1, x1, r1), (i2, h2, x2, r2) = runs
    assert r1 >= i1 - i1 // 4 - 2 and r2 == 0
    assert i1 == i2 == 40 and h1 == h2 and np.array_equal(x1, x2)


def test_single_gmres_rescaling_keeps_large_operators_finite():
    """An operator 2^20 times larger (rows growing by ~2^26 an iteration) would overflow float32
    within five unnormalised rows; with the default _RANGE the rows are rescaled and the solve
    matches the unscaled operator's (scaled by 2^-20) to float32 rounding."""
    A, B, b = _system(seed=4)
    xs = []
    for f in (1.0, 2.0 ** 20):
        gm = SingleGMRES(b.size, 30, _allsum)
        x = np.empty_like(b)
        its, _ = gm.solve(*_ops(f * A, B), b, x, 1e-5, 0.0, 200)
        xs.append((f * x, gm.rescales, its))
    (x1, r1, i1), (x2, r2, i2) = xs
    assert r2 > 0 and np.all(np.isfinite(x2)) and abs(i1 - i2) <= 1
    assert np.linalg.norm(b - A @ x2) <= 1.5e-5 * np.linalg.norm(b)
    assert np.linalg.norm(x2 - x1) <= 1e-4 * np.linalg.norm(x1)


def test_single_gmres_subtract_in_blocks(monkeypatch):
    """The Gram-Schmidt update t -= h @ V a block at a time, with the norm of the result: against
    float64 arithmetic, over whole blocks and a partial last one (a block of 2 chunks here).  t's
    entries round once per product and subtraction (float32: ~1e-7 of the terms' size); the norm sums
    in float32 over chunks of 8192 and in float64 over them (~1e-8 here, as _dots)."""
    import vecontact.solver.single as single
    monkeypatch.setattr(single, "_BLOCK", 2 * single._CHUNK)
    rng = np.random.default_rng(2)
    n = 5 * single._CHUNK + 123
    V = rng.standard_normal((4, n)).astype(np.float32)
    h = rng.standard_normal(4).astype(np.float32)
    t = rng.standard_normal(n).astype(np.float32)
    ref = t.astype(np.float64) - h.astype(np.float64) @ V.astype(np.float64)
    gm = SingleGMRES(n, 3, _allsum)
    assert gm.u.size == 2 * single._CHUNK                         # a block, not a whole vector
    tt = gm._subtract(V, h, t)
    scale = np.abs(h).sum() * np.abs(V).max() + np.abs(t).max()
    assert np.max(np.abs(t - ref)) <= 4 * 6e-8 * scale
    assert abs(tt / float(ref @ ref) - 1) <= 1e-6


# double precision throughout: the reference of the float32 variants
_DOUBLE = {"vc_changing_precision": "double", "vc_cycle_precision": "double", "vc_pc_range_max": "0",
           "vc_mixed_reduction_max": "0", "vc_single_exact_reduction_max": "0"}


def _solve(N, v, sigma0, options):
    fft, h, hn = paper_case(N)
    t0 = fft.single_transforms
    r = solve_contact(fft, L_PAPER, h, hn, v, sigma0, tolerance=1e-8, store=("pressure",), petsc_options=options)
    return r, fft.gather(r.pressure > 0), (fft.single_transforms - t0) / 2


@pytest.mark.parametrize("sigma0, mode, range_max, mixed", [
    (1.0e6, "free", 1e30, "on"), (1.0e5, "contact", 1e30, "on"), (1.0e6, "free", 1.0, "on"),
    (1.0e5, "contact", 1.0, "on"), (1.0e6, "free", 1.0, "off"), (1.0e5, "contact", 1.0, "off")])
def test_single_steps_same_solution(sigma0, mode, range_max, mixed):
    """float32 basis with float32 pairs (range_max above the stiffness's range, 4e3 here) and with
    float64 pairs (range_max 1; the preconditioners' pairs too: pc_range_max), these with mixed pairs
    (the operator's backward and the free-set preconditioner's forward transform in float32) or not."""
    one, act1, pairs1 = _solve(256, 10.0, sigma0, {"vc_changing_precision": "single",
                                                   "vc_single_range_max": str(range_max),
                                                   "vc_pc_range_max": str(range_max), "vc_mixed_pairs": mixed,
                                                   "vc_mixed_reduction_max": "0"})
    two, act2, pairs2 = _solve(256, 10.0, sigma0, _DOUBLE)
    assert one.converged and two.converged and max(one.residual, two.residual) <= 1e-8
    assert one.diagnostics["step_modes"][-1][1] == mode
    d1, d2 = one.diagnostics, two.diagnostics
    assert d1["single_iterations"] > 0.3 * one.linear_iterations and d2["single_iterations"] == 0
    assert d1["float32_pairs"] == (range_max > 1) and not d2["float32_pairs"]
    # mixed pairs: two an iteration of a float32-basis step (operator and preconditioner), at most
    with_mixed = range_max <= 1 and mixed == "on"
    assert (d1["mixed_pairs"] >= d1["single_iterations"]) if with_mixed else d1["mixed_pairs"] == 0
    assert d1["mixed_pairs"] <= 2 * d1["single_iterations"] + 2 * one.iterations and d2["mixed_pairs"] == 0
    assert (pairs1 > 0.3 * one.fft_pairs) if range_max > 1 else pairs1 == 0
    assert pairs2 == 0
    differ = int(np.count_nonzero(act1 != act2))      # points on the contact line may fall either way
    assert differ <= 4, differ
    assert abs(one.area - two.area) <= differ / 256 ** 2
    assert abs(one.mu / two.mu - 1) <= 1e-6, (one.mu, two.mu)
    # float32 changes only the rounding of the loose steps: the same number of Newton steps, give or take one
    assert abs(one.iterations - two.iterations) <= 1


@pytest.mark.parametrize("sigma0, mode", [(1.0e6, "free"), (1.1e5, "contact")])
def test_petsc_steps_mixed_same_solution(sigma0, mode):
    """The steps PETSc solves (here the exact ones: single_exact_reduction_max 0) with mixed pairs in
    their operator (mixed_reduction_max, default) against float64 pairs (0): the same solution and Newton steps; every
    mixed pair is an iteration of such a step (one operator product each)."""
    petsc = {"vc_single_exact_reduction_max": "0"}
    one, act1, _ = _solve(256, 10.0, sigma0, petsc)
    two, act2, _ = _solve(256, 10.0, sigma0, dict(petsc, vc_mixed_reduction_max="0"))
    d1, d2 = one.diagnostics, two.diagnostics
    assert d1["step_modes"][-1][1] == mode
    petsc_its = one.linear_iterations - d1["single_iterations"]
    assert 0 < d1["mixed_pairs"] <= petsc_its and d2["mixed_pairs"] == 0
    _same_path(one, act1, two, act2)


@pytest.mark.parametrize("sigma0, mode", [(1.0e6, "free"), (1.1e5, "contact")])
def test_exact_steps_single_same_solution(sigma0, mode):
    """Exact steps with a float32 basis (single_exact_reduction_max, default) against PETSc's float64
    one (0): the same solution and Newton steps; the exact step ran in single precision, flexible,
    watched by the measure stop (its looks: the monitor of single.py).  Both carry the last step's
    directions into the exact step (carry_modulus_min opened below this grid's modulus range, 82):
    without them the float32 exact step of the contact case stops on its 2-norm atol just short of the
    measure and one short exact step more follows (test_solver_carry.py).  The contact-set steps' 2-norm
    cap is lowered 25x (inner_atol_factor 0.2, default 5) so that only the measure stop can end the
    exact step: with the default cap, whether the stop looks before the cap ends the step turns on the
    start (at 1.1e5 one look with coarse_tol 0.1, none with 0.3; with the lower cap one or two looks
    at 1e5-2e5 with either)."""
    opts = dict(CARRY_OPEN, vc_inner_atol_factor="0.2")
    one, act1, _ = _solve(256, 10.0, sigma0, opts)
    two, act2, _ = _solve(256, 10.0, sigma0, dict(opts, vc_single_exact_reduction_max="0"))
    d1, d2 = one.diagnostics, two.diagnostics
    assert d1["step_modes"][-1][1] == mode
    exact = np.diff(d1["linear_history"])[-1]          # the last step's Krylov iterations
    assert d1["single_iterations"] - d2["single_iterations"] >= exact > 0
    assert len(d1["measure_checks"]) >= 1
    _same_path(one, act1, two, act2)


def _same_path(one, act1, two, act2):
    """Both converged to the solver's tolerance, the same Newton steps with Krylov iterations within
    one cycle of 20 each, at most 4 points (on the contact line) in another set, μ to 1e-6."""
    assert one.converged and two.converged and max(one.residual, two.residual) <= 1e-8
    h1, h2 = np.diff(one.diagnostics["linear_history"]), np.diff(two.diagnostics["linear_history"])
    assert len(h1) == len(h2) and np.all(np.abs(h1 - h2) <= 20), (h1, h2)
    differ = int(np.count_nonzero(act1 != act2))
    assert differ <= 4, differ
    assert abs(one.mu / two.mu - 1) <= 1e-6, (one.mu, two.mu)


def test_single_cycles_same_solution():
    """cycle_precision single: once the free-set steps cycle (changing steps capped at 10 iterations:
    the first uses its cap, the cycles start), the steps PETSc solves run its float64 FGMRES over GMRES
    cycles with a float32 basis (subset.SingleCycles) instead of PETSc's float64 cycles.  Both cycles
    are unpreconditioned GMRES with the same restart, so the steps take the same iterations up to
    rounding (one cycle each), and the answer is the same to the solver's tolerance."""
    base = {"vc_changing_precision": "double", "vc_cycle_after_cap": "1", "vc_lin_maxit_changing": "10"}
    one, act1, pairs1 = _solve(256, 10.0, 1.0e6, dict(base, vc_cycle_precision="single"))
    two, act2, pairs2 = _solve(256, 10.0, 1.0e6, dict(base, vc_cycle_precision="double", vc_pc_range_max="0"))
    d1, d2 = one.diagnostics, two.diagnostics
    assert d1["step_modes"][-1][1] == "free"
    # float32 only in the cycles (changing_precision double), and they did most of the work
    assert d1["single_iterations"] > 0.5 * one.linear_iterations and d2["single_iterations"] == 0
    assert pairs1 > 0.3 * one.fft_pairs and pairs2 == 0
    _same_path(one, act1, two, act2)


@pytest.mark.parametrize("sigma0, mode", [(1.0e6, "free"), (1.0e5, "contact")])
def test_float32_preconditioner_pairs(sigma0, mode):
    """pc_range_max: where the steps' own pairs are float64 (single_range_max 1, below the stiffness's
    range of 4e3 here), the preconditioners of FGMRES run float32 pairs up to pc_range_max, and only
    there: the float32 GMRES cycles of the free set (from the second step on: the first uses its cap of
    10) and the stiffness of the contact-set steps (PETSc's FGMRES in double).  FGMRES applies its
    operator in float64 to the preconditioned vectors it keeps, so the answer is the same to the
    solver's tolerance, and the steps' iterations are within one cycle (free) or a few (contact)."""
    base = {"vc_changing_precision": "double", "vc_single_range_max": "1"}
    if mode == "free":
        base.update(vc_cycle_after_cap="1", vc_lin_maxit_changing="10")
    one, act1, pairs1 = _solve(256, 10.0, sigma0, dict(base, vc_pc_range_max="1e30"))
    two, act2, pairs2 = _solve(256, 10.0, sigma0, dict(base, vc_pc_range_max="1"))
    d1, d2 = one.diagnostics, two.diagnostics
    assert d1["step_modes"][-1][1] == mode
    assert d1["float32_pairs"] and not d2["float32_pairs"]
    assert pairs1 > 0.3 * one.fft_pairs and pairs2 == 0
    _same_path(one, act1, two, act2)


def test_single_steps_only_where_allowed():
    # the user's own Krylov tolerances (POLICY_OFF) or methods, and a floor above every changing rtol
    # with exact steps in PETSc: no float32 basis; no float32 pairs either without pc_range_max
    # (preconditioners of FGMRES), and none with it where the user chose the Krylov methods (theirs need
    # not be flexible)
    for options in ({"ksp_rtol": "1e-2", "contact_ksp_rtol": "1e-2", "vc_pc_range_max": "0"},
                    {"vc_single_rtol_min": "0.5", "vc_single_rtol_min_contact": "0.5", "vc_cycle_precision": "double",
                     "vc_pc_range_max": "0", "vc_single_exact_reduction_max": "0"},
                    {"ksp_type": "gmres", "contact_ksp_type": "fgmres", "vc_pc_range_max": "1e30"}):
        r, _, pairs = _solve(128, 10.0, 1.0e6, options)
        assert r.converged and pairs == 0, options


def test_single_gmres_dots_sum_in_double():
    """The Gram-Schmidt products: float32 sums of at most 8192 terms, then float64 over the chunks.
    Against float64 products, the error relative to |v_j| |t| stays at the chunk's float32 rounding
    (~sqrt(8192) x 6e-8 / sqrt(n / 8192) here, measured 1.6e-9), where one float32 sum over all
    2e6 terms (BLAS sgemv) errs by 8e-8."""
    rng = np.random.default_rng(1)
    n = 2_000_000
    V = (rng.standard_normal((3, n)) + 0.5).astype(np.float32)
    t = (rng.standard_normal(n) + 0.5).astype(np.float32)
    gm = SingleGMRES(8, 2, _allsum)
    ref = V.astype(np.float64) @ t.astype(np.float64)
    scale = np.linalg.norm(V.astype(np.float64), axis=1) * np.linalg.norm(t.astype(np.float64))
    assert np.max(np.abs(gm._dots(V, t) - ref) / scale) < 1e-8
    assert np.max(np.abs(gm._dots(V[:, :12345], t[:12345]) - V[:, :12345].astype(float) @ t[:12345])
                  / scale) < 1e-8                                     # a partial last chunk


def test_basis_stores_kept_for_a_few_more_points_and_longer_restarts():
    """_Single.gmres makes a store for the restart the budget allows (``capacity``) on
    store_headroom (5 %) more points than asked, and keeps it for later solves that fit: a new store's
    pages fault in again on first write.  Beyond it (a larger set, or the flexible method's
    preconditioned vectors in the work store) only the store that is too small is made again."""
    from vecontact.solver.contactset import ContactSetStep
    from vecontact.solver.operator import ContactOperator
    from vecontact.solver.settings import SolverSettings
    from vecontact.solver.snes import petsc

    fft, h, hn = paper_case(64)
    op = ContactOperator(fft, L_PAPER, hn, 1.0, 1e5, h)
    step = ContactSetStep(op, op.kappa, petsc(), "storetest_", SolverSettings())
    try:
        sg = step.single_context()
        stores = lambda: sg._stores["plain"]
        gm = sg.gmres("plain", 100, 10, _allsum, False, capacity=30)
        first = stores()
        assert first[0].size >= SingleGMRES.sizes(105, 30, False)[0] and gm.V.shape == (11, 100)
        gm = sg.gmres("plain", 104, 30, _allsum, False, capacity=30)
        assert stores()[0] is first[0] and stores()[1] is first[1] and gm.V.shape == (31, 104)
        gm = sg.gmres("plain", 104, 30, _allsum, True, capacity=30)       # FGMRES: Z in the work store
        assert stores()[0] is first[0] and stores()[1] is not first[1] and gm.Z.shape == (30, 104)
        gm = sg.gmres("plain", 120, 10, _allsum, False, capacity=30)       # fits: entries, not shape
        assert stores()[0] is first[0] and gm.V.shape == (11, 120)
        gm = sg.gmres("plain", 120, 30, _allsum, False, capacity=30)       # 20 % more points
        assert stores()[0] is not first[0] and gm.V.shape == (31, 120)
    finally:
        step.release()
