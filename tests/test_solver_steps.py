"""Both Newton-step solvers, on the contact set (contactset.py) and on the free set (freeset.py), solve
the Newton system of the semismooth method exactly up to their inner Krylov tolerance.

The check applies the generalised Jacobian independently, J x = P_C x + P_F m x / kappa (snes.py),
one FFT pair, to the step's answer x for a random right-hand side r.
"""
import numpy as np
import pytest
from mpi4py import MPI

from vecontact.core.pfft import SlabFFT
from vecontact.physics.modulus import HavriliakNegami
from vecontact.solver.contactset import ContactSetStep
from vecontact.solver.freeset import FreeSetStep
from vecontact.solver.operator import ContactOperator
from vecontact.solver.settings import SolverSettings
from vecontact.solver.snes import petsc
from vecontact.solver.subset import Mixed, Workspace

N, L = 32, 1e-4


def _operator():
    fft = SlabFFT(MPI.COMM_SELF, N, planner="estimate", wisdom_file=False)
    rng = np.random.default_rng(5)
    k = np.hypot(np.fft.fftfreq(N, 1 / N)[:, None], np.fft.rfftfreq(N, 1 / N)[None, :])
    H = np.where((k >= 1) & (k <= 8), np.maximum(k, 2.0) ** -1.8, 0.0) * np.exp(2j * np.pi * rng.random(k.shape))
    h = np.fft.irfft2(H, s=(N, N))
    h *= 1e-8 / h.std()
    # 1 m/s: Im E(q_x v) ~ Re E on the grid, a strongly non-symmetric stiffness
    return ContactOperator(fft, L, HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10, 0.5), 1.0, 1e4, h)


def _apply_step(step, act, r):
    """x = step.apply(r) on the contact set ``act`` (bool N x N); r, x as N x N arrays."""
    PETSc = petsc()
    rv = PETSc.Vec().createSeq(N * N)
    xv = rv.duplicate()
    try:
        step.set_active(act, int(np.count_nonzero(act)))
        rv.getArray()[:] = r.ravel()
        step.apply(None, rv, xv)
        return xv.getArray(readonly=True).reshape(N, N).copy()
    finally:
        rv.destroy()
        xv.destroy()


def _jacobian(op, act, x):
    """The generalised Jacobian applied independently of the steps: J x = P_C x + P_F m x / kappa."""
    return np.where(act, x, op.fft.apply(x, op.m / op.kappa))


@pytest.mark.parametrize("area", [0.1, 0.6])
@pytest.mark.parametrize("kind, cycle, precision", [(ContactSetStep, 0, "double"), (FreeSetStep, 0, "double"),
                                                     (FreeSetStep, 5, "double"), (FreeSetStep, 5, "single")])
def test_step_solves_the_newton_system(kind, cycle, precision, area):
    """Inner rtol 1e-13 on a 32^2 grid: |J x - r| <= 1e-9 max|r| leaves room for the FFT's rounding
    (m / kappa amplifies it by at most max|m| / kappa < 1e3, asserted) and nothing for a wrong
    elimination: dropping the contact step's rigid shift or the free step's coupling term m P_C r_C
    (both tried) fails by O(1).  ``cycle``: the free set solved by FGMRES over GMRES(5) cycles
    (free_cycle), whose iterations come in whole cycles; ``precision`` single: the cycles with a float32
    basis (SingleCycles) under the float64 FGMRES, which still meets the tight tolerance."""
    op = _operator()
    act = op.hhat > np.quantile(op.hhat, 1.0 - area)       # the highest points are in contact
    step = kind(op, op.kappa, petsc(), "steptest_", SolverSettings(free_cycle=cycle, cycle_precision=precision))
    try:
        if cycle:
            step.set_active(act, int(np.count_nonzero(act)))
            step.start_cycles()
        step.set_tolerances(1e-13, 0.0, 500)
        r = np.random.default_rng(7).standard_normal((N, N))
        x = _apply_step(step, act, r)
        jx = _jacobian(op, act, x)
        assert np.max(np.abs(jx - r)) <= 1e-9 * np.max(np.abs(r))
        assert step.solves == 1 and 0 < step.iterations < 500
        assert step.iterations % max(cycle, 1) == 0
        assert np.max(np.abs(op.m)) / op.kappa < 1e3      # the rounding bound of the docstring holds
    finally:
        step.release()


def test_the_two_step_types_share_one_workspace():
    """ncp_solve gives both step types one Workspace, so a solve holds their whole-grid arrays once.
    Alternating between them on sets of other sizes, each still solves its Newton system (the bound of
    test_step_solves_the_newton_system): a shared Grid's buffer is cleared of the other step's points
    before a product (Grid.scatter).  Clearing only a step's own previous points, as each step did
    while it had its own Grid, fails here by O(1).  The float32 Grid is shared too: the contact set's
    FGMRES preconditioner and the free set's float32 cycles both form products on it."""
    op = _operator()
    settings = SolverSettings(free_cycle=5, cycle_precision="single")
    work = Workspace(op.fft)
    steps = dict(contact=ContactSetStep(op, op.kappa, petsc(), "steptest_", settings, work),
                 free=FreeSetStep(op, op.kappa, petsc(), "steptest_", settings, work))
    r = np.random.default_rng(7).standard_normal((N, N))
    try:
        assert steps["contact"].grid is steps["free"].grid and steps["contact"].w is steps["free"].w
        for mode, area in [("contact", 0.1), ("free", 0.6), ("contact", 0.3), ("free", 0.2), ("contact", 0.1)]:
            act = op.hhat > np.quantile(op.hhat, 1.0 - area)
            step = steps[mode]
            if mode == "free":
                step.set_active(act, int(np.count_nonzero(act)))
                step.start_cycles()
            step.set_tolerances(1e-13, 0.0, 500)
            x = _apply_step(step, act, r)
            assert np.max(np.abs(_jacobian(op, act, x) - r)) <= 1e-9 * np.max(np.abs(r)), (mode, area)
        assert steps["contact"].ran_float32_pairs and steps["free"].ran_float32_pairs
        assert work.float32_grid() is steps["free"].float32_grid()
    finally:
        for step in steps.values():
            step.release()


@pytest.mark.parametrize("precision", ["single", "double"])
def test_cycled_free_set_step_counts_and_caps_inner_iterations(precision):
    """free_cycle 5, cycling: the cap counts GMRES iterations, rounded up to whole cycles (12 -> 3 cycles, 15
    iterations), and every cycle runs all its 5 (an rtol the solve cannot meet makes it use the cap);
    the FFT pairs show it: 1 for the step, then per cycle 5 (the operator: the cycles' GMRES is
    unpreconditioned) + 1 (the outer FGMRES's operator).  The same after the free set changed size
    (select remakes the KSP's operators: PETSc's nested PC must not fall back to another one), and in
    both precisions of the cycles (cycle_precision; single: every cycle iteration in float32)."""
    op = _operator()
    step = FreeSetStep(op, op.kappa, petsc(), "steptest_", SolverSettings(free_cycle=5, cycle_precision=precision))
    try:
        for q in (0.4, 0.5):                                # the second set: another size
            act = op.hhat > np.quantile(op.hhat, q)
            step.set_active(act, int(np.count_nonzero(act)))
            step.start_cycles()                             # the policy's call once a step used its cap
            step.set_tolerances(1e-30, 0.0, 12)
            op.fft.reset_counters()
            it0, s0 = step.iterations, step.single_iterations
            _apply_step(step, act, np.random.default_rng(7).standard_normal((N, N)))
            assert step.iterations - it0 == 15
            assert step.single_iterations - s0 == (15 if precision == "single" else 0)
            assert op.fft.pairs == 1 + 3 * (5 + 1)
        assert step.solves == 2
    finally:
        step.release()


def test_free_set_step_in_full_contact_is_the_identity():
    """With every point in contact J = identity: the free-set step returns r without an inner solve."""
    op = _operator()
    step = FreeSetStep(op, op.kappa, petsc(), "steptest_", SolverSettings())
    try:
        r = np.arange(N * N, dtype=float).reshape(N, N)
        np.testing.assert_array_equal(_apply_step(step, np.ones((N, N), dtype=bool), r), r)
        assert step.solves == 0
    finally:
        step.release()


@pytest.mark.parametrize("kind", [ContactSetStep, FreeSetStep])
def test_step_iterates_even_when_its_atol_is_met_at_once(kind):
    """ksp_min_it 1 (settings.PETSC_*_DEFAULTS): with an atol far above the first residual the inner
    Krylov solve still takes an iteration and moves x toward J^{-1} r.  Without it the step returned a
    zero inner update: a Newton step that left the iterate where it was (tol 0.1, 512^2: residuals
    0.141, 0.141, 0.141; benchmarks/RESULTS.md)."""
    op = _operator()
    act = op.hhat > np.quantile(op.hhat, 0.7)
    step = kind(op, op.kappa, petsc(), "steptest_", SolverSettings())
    try:
        step.set_tolerances(0.1, 1e30, 50)
        r = np.random.default_rng(7).standard_normal((N, N))
        x = _apply_step(step, act, r)
        assert step.solves == 1 and step.iterations == 1
        # one iteration from zero reduces the Newton residual |J x - r| below |r| (GMRES is monotone;
        # the eliminated rows are exact), by far more than rounding
        jx = _jacobian(op, act, x)
        assert np.linalg.norm(jx - r) < 0.99 * np.linalg.norm(r)
    finally:
        step.release()


@pytest.mark.parametrize("kind", [ContactSetStep, FreeSetStep])
def test_mixed_step_meets_its_tolerance(kind):
    """set_tolerances(mixed=True): the PETSc solve's operator takes its backward transform in float32
    (one mixed pair an iteration, counted).  To rtol 1e-6 the step solves the Newton system as well as
    with float64 pairs (measured 1.3e-6 and 2.0e-6 of max|r| both ways); to rtol 1e-10 it stalls near
    the float32 rounding of A z (4.5e-7) where float64 pairs reach 2e-10: the limit
    StepPolicy.mixed_reduction keeps the mixed steps away from (mixed_reduction_max)."""
    op = _operator()
    act = op.hhat > np.quantile(op.hhat, 0.7)
    r = np.random.default_rng(7).standard_normal((N, N))
    err = {}
    for rtol in (1e-6, 1e-10):
        for mixed in (True, False):
            step = kind(op, op.kappa, petsc(), "steptest_", SolverSettings())
            try:
                step.set_tolerances(rtol, 0.0, 200, mixed=mixed)
                x = _apply_step(step, act, r)
                err[rtol, mixed] = np.max(np.abs(_jacobian(op, act, x) - r)) / np.max(np.abs(r))
                assert step.mixed_pairs == (step.iterations if mixed else 0) and step.iterations > 5
            finally:
                step.release()
    assert err[1e-6, True] <= min(1e-5, 1.5 * err[1e-6, False]), err
    assert err[1e-10, False] <= 1e-8 < err[1e-10, True], err


def test_products_fold_the_normalisation_into_their_input():
    """Grid.product_of (and Mixed's) takes the backward transform's 1/N^2 on the |S| entries of x
    when unscaled: bit for bit SlabFFT.apply of the scattered x (1/N^2 a power of two), and
    SlabFFT.apply's own scale pass otherwise (to rounding of a scaled multiplier)."""
    op = _operator()
    fft = op.fft
    work = Workspace(fft)
    idx = np.flatnonzero((op.hhat > np.quantile(op.hhat, 0.6)).ravel())
    x = np.random.default_rng(11).standard_normal(idx.size)
    full = np.zeros(N * N)
    full[idx] = x
    full = full.reshape(N, N)
    g, g32 = work.grid, work.float32_grid()
    g.product_of(idx, x, op.c, 1.0)
    assert np.array_equal(g.out, fft.apply(full, op.c))
    g.product_of(idx, x, op.m, 0.37)
    assert np.max(np.abs(g.out - fft.apply(full, op.m * 0.37))) <= 1e-14 * np.max(np.abs(g.out))

    class Step:
        mixed_pairs = 0
    mixed = Mixed(g, g32, Step)
    mixed.product_of(idx, x, op.c, 1.0)
    assert np.array_equal(g32.out, fft.apply_across(fft.single(), full, op.c, fft.single().real_array()))
    assert Step.mixed_pairs == 1


@pytest.mark.parametrize("area", [0.05, 0.4])
def test_the_vi_method_solves_its_reduced_step_on_the_contact_set(area):
    """PETSc's VI Newton (vi.py) solves m_II y = x on its inactive set I with the gap held on the rest A;
    ViNewton.stiffness_inverse does it through the contact-set step on A.  Checked against a dense solve
    of m_II, its columns made by one FFT pair per unit vector: at vi_step_rtol 1e-13 the two
    agree to 1e-10 of max|y| (that rtol times m_II's condition, below 1e3, asserted; measured 1e-14).
    A right-hand side without the 1/kappa, or with a gap of 1e-3 on A instead of 0 (both tried), fails
    it.  The step's iterations are counted; with A empty nothing is done (the compliance PC's case)."""
    from vecontact.solver.newton import NewtonState
    from vecontact.solver.vi import ViNewton
    PETSc = petsc()
    op = _operator()
    act = op.hhat > np.quantile(op.hhat, 1.0 - area)
    idx = np.flatnonzero(~act.ravel())
    settings = SolverSettings(edge_window=0, vi_step_rtol=1e-13, ksp_max_it=500)
    vi = ViNewton(NewtonState(op), PETSc, ContactSetStep(op, op.kappa, PETSc, "vitest_", settings))
    xv = PETSc.Vec().createSeq(idx.size)
    yv = xv.duplicate()
    try:
        x = np.random.default_rng(11).standard_normal(idx.size)
        xv.getArray()[:] = x
        assert vi.stiffness_inverse(idx, xv, yv)
        y = yv.getArray(readonly=True).copy()
        cols = np.empty((idx.size, idx.size))
        e = np.zeros((N, N))
        for j, k in enumerate(idx):
            e.flat[k] = 1.0
            cols[:, j] = op.fft.apply(e, op.m).ravel()[idx]
            e.flat[k] = 0.0
        want = np.linalg.solve(cols, x)
        assert np.linalg.cond(cols) < 1e3          # the bound of the docstring holds (44 and 364 measured)
        assert np.max(np.abs(y - want)) <= 1e-10 * np.max(np.abs(want))
        assert 0 < vi.step.iterations < 500
        assert not vi.stiffness_inverse(np.arange(N * N), None, None)       # A empty: x and y untouched
    finally:
        vi.release()
        for obj in (xv, yv):
            obj.destroy()


def test_the_vi_steps_tighten_with_the_measure():
    """SolverSettings.vi_rtol: a VI step's Krylov rtol is its iterate's measure within [vi_step_rtol,
    vi_step_rtol_max], and vi_step_rtol alone where the cap is not above it."""
    S = SolverSettings()
    assert (S.vi_step_rtol, S.vi_step_rtol_max) == (1e-5, 1e-2)
    assert [S.vi_rtol(m) for m in (np.inf, 84.0, 1e-2, 3e-4, 1e-5, 1e-9)] == [1e-2, 1e-2, 1e-2, 3e-4, 1e-5, 1e-5]
    fixed = SolverSettings(vi_step_rtol=1e-6, vi_step_rtol_max=1e-7)
    assert [fixed.vi_rtol(m) for m in (np.inf, 1e-3, 1e-9)] == [1e-6] * 3


_VI_BT = ["-snes_linesearch_type", "bt", "-snes_max_fail", "300"]      # the fallback's line search


def _vi_case():
    """The VI tests' 64^2 surface (the reference cases' spectrum, seed 4) and its SlabFFT; the paths
    round with the FFT plans: the estimate planner's from empty wisdom (conftest.py)."""
    from reference.cases import L_PAPER, small_spectrum
    from reference.dense import random_surface
    n = 64
    h = random_surface(n, L_PAPER, small_spectrum(n), seed=4)
    return SlabFFT(MPI.COMM_SELF, n, planner="estimate", wisdom_file=False), h


def _vi_solve(fft, h, mod, v, *options, **kwargs):
    """PETSc's VI method with ``options`` on ``_vi_case``'s surface at sigma0 = 1e-3 |E(8 q0 v)|,
    the pressure stored."""
    from reference.cases import L_PAPER
    from vecontact.solver import solve_contact
    sigma0 = 1e-3 * abs(complex(mod(np.array([2 * np.pi / L_PAPER * 8 * v]))[0]))
    return solve_contact(fft, L_PAPER, h, mod, v, sigma0, store=("pressure",),
                         petsc_options=["-snes_type", "vinewtonrsls", *options], **kwargs)


def test_vi_steps_go_loose_while_the_line_search_takes_them_whole():
    """PETSc's VI method with the bt line search on the tests' 64^2 surface.  ViNewton.iterate, at each
    iterate (its measure the monitor's): the next step's rtol is SolverSettings.vi_rtol of the
    measure (1e-2 far from the solution), but vi_step_rtol after a loose step that bt cut (more than
    one residual evaluation; the broad rubber at 30 m/s has such steps, measured).  The SLS rubber at
    1 mm/s (loss angle up to 79 deg, 18 % in contact) converges to the same contact set and mu as
    with every step at 1e-5, in fewer FFT pairs (measured 474 against 752).  With PETSc's basic line
    search (the VI method's default), which judges no step, every step is at vi_step_rtol."""
    from reference.cases import NU
    from vecontact.physics.modulus import SLS, HavriliakNegami
    from vecontact.solver.vi import ViNewton
    fft, h = _vi_case()
    S = SolverSettings()
    iterate = ViNewton.iterate
    log = []

    def spy(self, snes, measure):
        before = (self._loose, self._evals)
        iterate(self, snes, measure)
        log.append((measure, *before, self.rtol))

    def run(mod, v, *options):
        log.clear()
        seen = []
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(ViNewton, "iterate", spy)
            r = _vi_solve(fft, h, mod, v, *options, monitor=lambda N, it, m: seen.append(m))
        assert r.converged and 0.1 < r.area < 0.3
        assert [m for m, *_ in log] == seen and len(seen) == r.iterations + 1
        return r, list(log)

    _, steps = run(HavriliakNegami(3e6, 3e10, 0.5, 0.5, 1e-10, NU), 30.0, *_VI_BT)
    cut = [loose and evals > 1 for _, loose, evals, _ in steps]
    assert [t for *_, t in steps] == [S.vi_step_rtol if k else S.vi_rtol(m) for (m, *_), k in zip(steps, cut)]
    assert any(cut) and steps[0][-1] == S.vi_step_rtol_max
    sls = SLS(3e6, 3e8, 1e-5, NU)
    loose, steps = run(sls, 0.001, *_VI_BT)
    assert steps[0][-1] == S.vi_step_rtol_max
    fixed, steps = run(sls, 0.001, *_VI_BT, "-vc_vi_step_rtol_max", str(S.vi_step_rtol))
    assert {t for *_, t in steps} == {S.vi_step_rtol}
    assert np.array_equal(loose.pressure > 0, fixed.pressure > 0)
    assert abs(loose.mu - fixed.mu) <= 1e-8 * abs(fixed.mu)
    assert loose.fft_pairs < 0.8 * fixed.fft_pairs, (loose.fft_pairs, fixed.fft_pairs)
    _, steps = run(sls, 0.001)
    assert {t for *_, t in steps} == {S.vi_step_rtol}


def test_step_precision_by_the_reduction_a_step_must_make():
    """SolverSettings.step_precision: a float32 basis up to single_exact_reduction_max, mixed pairs in
    PETSc's operator beyond it up to mixed_reduction_max, float64 beyond both; no float32 basis where
    it is not allowed (the free set's cycles) or its knob is 0."""
    S = SolverSettings()
    assert (S.single_exact_reduction_max, S.mixed_reduction_max) == (1e5, 1e5)
    assert [S.step_precision(r) for r in (1e2, 1.0 / 1e-5, 1e6)] == [(True, False), (True, False), (False, False)]
    assert S.step_precision(1e2, float32_basis=False) == (False, True)
    wide = SolverSettings(single_exact_reduction_max=1e3, mixed_reduction_max=1e6)
    assert [wide.step_precision(r) for r in (1e3, 1e4, 1e7)] == [(True, False), (False, True), (False, False)]
    assert SolverSettings(single_exact_reduction_max=0).step_precision(1.0) == (False, True)


def test_vi_step_after_one_that_ran_out_keeps_a_longer_basis(monkeypatch):
    """A VI step whose FGMRES used all of ksp_max_it short of its rtol is followed by one with the restart
    vi_capped_restart instead of inner_restart_max (restarted FGMRES stagnated on such steps: a 512^2
    SLS case took 70 272 pairs in them, RESULTS.md); a step after one that converged goes back.  The
    SLS rubber at 1 mm/s on the tests' 64^2 surface with the bt line search, caps small enough that
    steps run out (ksp_max_it 40, inner_restart_max 12, vi_capped_restart 40): the restart of every
    step follows the rule, with the float32 basis (single.py) and in PETSc's float64 FGMRES
    (single_range_max below the range), and the answers are the default's (contact set, mu to 1e-8).
    With -contact_ksp_gmres_restart the user's restart holds."""
    from reference.cases import NU
    from vecontact.physics.modulus import SLS
    from vecontact.solver import single
    from vecontact.solver.vi import ViNewton
    # the longer basis stays within the Krylov memory the farm counts (farm.memory): 400 on a 512^2
    # rank where the active set is small, less where it is large, never below inner_restart_max's
    S, n = SolverSettings(), 512 * 512
    for n_active in (n // 20, n // 4, n // 2, 7 * n // 10):
        restart = S.vi_restart(512, n, n_active)
        assert S.inner_restart(n_active) <= restart <= S.vi_capped_restart
        assert restart == S.inner_restart(n_active) or 2 * 8 * (restart + 1) * n_active <= S.krylov_bytes(512, n)
    assert S.vi_restart(512, n, n // 20) == S.vi_capped_restart
    assert S.vi_restart(512, n, 7 * n // 10) == S.inner_restart(7 * n // 10)
    assert SolverSettings(vi_capped_restart=0).vi_restart(512, n, n // 20) == S.inner_restart(n // 20)
    fft, h = _vi_case()
    sls = SLS(3e6, 3e8, 1e-5, NU)
    default = _vi_solve(fft, h, sls, 0.001, *_VI_BT)
    caps = ("-vc_ksp_max_it", "40", "-vc_inner_restart_max", "12", "-vc_vi_capped_restart", "40")
    made = []
    init, inverse = single.SingleGMRES.__init__, ViNewton.stiffness_inverse

    def spy_init(self, n_loc, restart, *args, **kwargs):
        made.append(restart)
        init(self, n_loc, restart, *args, **kwargs)

    def run(*options):
        steps = []

        def spy_inverse(self, idx, x, y):
            its, n = self.step.iterations, len(made)
            done = inverse(self, idx, x, y)
            if done:
                steps.append((self.step.iterations - its, made[n:] or [self.petsc_restart or 12]))
            return done

        monkeypatch.setattr(ViNewton, "stiffness_inverse", spy_inverse)
        r = _vi_solve(fft, h, sls, 0.001, *_VI_BT, *caps, *options)
        assert r.converged and 0.1 < r.area < 0.3
        assert np.array_equal(r.pressure > 0, default.pressure > 0)
        assert abs(r.mu - default.mu) <= 1e-8 * abs(default.mu)
        ran_out = [its >= 40 for its, _ in steps]
        assert any(ran_out[:-1]) and not all(ran_out), options
        return [restart for _, restart in steps], [False] + ran_out[:-1]

    monkeypatch.setattr(single.SingleGMRES, "__init__", spy_init)
    for options in ((), ("-vc_single_range_max", "10")):
        restarts, after = run(*options)
        assert restarts == [[40 if out else 12] for out in after], options
    # the user's restart: never replaced (the spy's 12 is "not set")
    restarts, _ = run("-vc_single_range_max", "10", "-contact_ksp_gmres_restart", "15")
    assert {r for r, in restarts} == {12}


def test_vi_steps_solve_with_a_float32_basis():
    """The VI method's steps (vi.py) keep a float32 basis where their pairs are float32 too (the
    stiffness's range at most single_range_max) and the exact steps' rule allows it for their 1 / rtol
    (at most 1e5: always, by default); else a float64 FGMRES, as with single_exact_reduction_max 0 or
    a single_range_max below the range.  The SLS rubber at 1 mm/s on the tests' 64^2 surface, with the
    bt line search: all three converge to the same contact set and mu (to 1e-8; measured 1e-13 on the
    SLS 256^2 and 512^2 scans); the diagnostics count the float32-basis iterations (all of them by
    default, none otherwise)."""
    from reference.cases import NU
    from vecontact.physics.modulus import SLS
    fft, h = _vi_case()
    sls = SLS(3e6, 3e8, 1e-5, NU)

    def run(*options):
        r = _vi_solve(fft, h, sls, 0.001, *_VI_BT, *options)
        assert r.converged and 0.1 < r.area < 0.3
        return r

    single = run()
    assert single.diagnostics["single_iterations"] == single.linear_iterations > 0
    assert single.diagnostics["float32_pairs"]
    for options in (("-vc_single_exact_reduction_max", "0"), ("-vc_single_range_max", "10")):
        double = run(*options)
        assert double.diagnostics["single_iterations"] == 0, options
        assert np.array_equal(single.pressure > 0, double.pressure > 0)
        assert abs(single.mu - double.mu) <= 1e-8 * abs(double.mu)
