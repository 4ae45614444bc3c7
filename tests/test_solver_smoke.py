"""Quick smoke tests of vecontact.solver (the full validation suite lives in tests/test_solver_*.py)."""
import math

import numpy as np
import pytest
from mpi4py import MPI

from vecontact.core.pages import huge_page_advice
from vecontact.core.pfft import SlabFFT
from vecontact.physics.modulus import Elastic, HavriliakNegami, SLS
from vecontact.solver import ContactResult, solve_contact
from vecontact.solver.settings import SolverSettings

COMM = MPI.COMM_SELF


def _fft(N):
    return SlabFFT(COMM, N, planner="estimate", wisdom_file=False)


def _sinusoid(fft, L, D, two_d=False):
    x = (np.arange(fft.row_start, fft.row_stop) * L / fft.N)[:, None]
    y = (np.arange(fft.N) * L / fft.N)[None, :]
    k = 2 * np.pi / L
    if two_d:
        return np.ascontiguousarray(D * np.cos(k * x) * np.cos(k * y))
    return np.ascontiguousarray(D * np.cos(k * x) + 0 * y)


def _random_surface(fft, L, hrms=1e-8, q1fac=8, seed=3):
    N = fft.N
    rng = np.random.default_rng(seed)
    kx = np.fft.fftfreq(N, 1 / N)[:, None]
    ky = np.fft.rfftfreq(N, 1 / N)[None, :]
    k = np.sqrt(kx ** 2 + ky ** 2)
    amp = np.where((k >= 1) & (k <= q1fac), np.maximum(k, 2.0) ** (-1.8), 0.0)
    H = amp * np.exp(2j * np.pi * rng.random(amp.shape))
    h = np.fft.irfft2(H, s=(N, N))
    h *= hrms / h.std()
    return np.ascontiguousarray(h[fft.row_start:fft.row_stop])


@pytest.mark.parametrize("method", ["snes", "pk"])
def test_westergaard(method):
    N, L, D, E, nu = 128, 1e-4, 1e-7, 1e7, 0.5
    fft = _fft(N)
    h = _sinusoid(fft, L, D)
    pstar = math.pi * E * D / ((1 - nu ** 2) * L)
    pbar = 0.2 * pstar
    r = solve_contact(fft, L, h, Elastic(E, nu), 0.0, pbar, method=method)
    assert isinstance(r, ContactResult) and r.converged, r.summary()
    a_exact = 2 / math.pi * math.asin(math.sqrt(pbar / pstar))
    assert abs(r.area - a_exact) <= 2.0 / N
    pmax = 2 * math.sqrt(pbar * pstar)
    assert abs(r.pressure.max() - pmax) / pmax < 0.005
    rr = pbar / pstar
    gap_exact = D * (1 - rr + rr * math.log(rr))
    assert abs(r.mean_gap - gap_exact) / gap_exact < 1e-3
    assert abs(r.mu) < 1e-12


def test_full_contact_mu_exact():
    N, L, D = 64, 1e-4, 1e-8
    fft = _fft(N)
    h = _sinusoid(fft, L, D)
    mod = HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10, 0.5)
    k = 2 * np.pi / L
    v = 1.0
    sigma0 = 10 * abs(mod(k * v)) * k * D  # far into full contact
    r = solve_contact(fft, L, h, mod, v, sigma0)
    assert r.converged and r.area == 1.0
    mu = k ** 2 * D ** 2 * mod(k * v).imag / (4 * (1 - mod.nu ** 2) * sigma0)
    assert abs(r.mu - mu) / mu < 1e-6
    assert abs(r.mu_geometric - mu) / mu < 1e-6


def test_snes_equals_pk_elastic():
    N, L = 128, 1e-4
    fft = _fft(N)
    h = _random_surface(fft, L)
    mod = Elastic(3e6, 0.5)
    sig = 2e3
    a = solve_contact(fft, L, h, mod, 0.0, sig, method="snes")
    b = solve_contact(fft, L, h, mod, 0.0, sig, method="pk")
    assert a.converged and b.converged
    assert np.count_nonzero((a.pressure > 0) != (b.pressure > 0)) <= 1
    assert abs(a.mean_gap - b.mean_gap) / abs(b.mean_gap) < 1e-6
    assert np.abs(a.pressure - b.pressure).max() / sig < 1e-5


def test_pk_rejects_viscoelastic():
    fft = _fft(32)
    h = _random_surface(fft, 1e-4, q1fac=4)
    with pytest.raises(ValueError):
        solve_contact(fft, 1e-4, h, SLS(3e6, 3e8, 1e-6, 0.5), 1.0, 1e4, method="pk")


def test_viscoelastic_mu_consistency_and_warm():
    N, L = 128, 1e-4
    fft = _fft(N)
    h = _random_surface(fft, L, q1fac=8)
    mod = SLS(3e6, 3e8, 1e-6, 0.5)
    r = solve_contact(fft, L, h, mod, 20.0, 3e4)
    assert r.converged, r.summary()
    assert r.mu > 0 and abs(r.mu - r.mu_geometric) < 0.05 * r.mu
    r2 = solve_contact(fft, L, h, mod, 20.0, 3.3e4, warm=r)
    assert r2.converged and r2.area >= r.area
    r3 = solve_contact(fft, L, h, mod, 20.0, 3.3e4, coarse=False)
    assert abs(r3.mu - r2.mu) < 1e-6 * r2.mu


def test_displacement_is_transformed_back_only_when_asked_for():
    """mu needs only the displacement's spectrum: without "displacement" in ``store`` the solve skips
    its backward transform (half an FFT pair) and nothing else changes, bit for bit."""
    N, L = 64, 1e-4
    fft = _fft(N)
    h = _random_surface(fft, L, q1fac=8)
    mod = SLS(3e6, 3e8, 1e-6, 0.5)
    full = solve_contact(fft, L, h, mod, 20.0, 3e4, store=("pressure", "gap", "displacement"))
    lean = solve_contact(fft, L, h, mod, 20.0, 3e4, store=("pressure",))
    assert full.converged and lean.converged
    assert lean.displacement is None and full.displacement is not None
    # the pairs are sums of level counts times weights: equal up to the rounding of that sum
    assert full.fft_pairs - lean.fft_pairs == pytest.approx(0.5, abs=1e-12 * full.fft_pairs)
    for key in ("area", "mu", "mu_geometric", "mean_gap", "residual"):
        assert getattr(lean, key) == getattr(full, key), key
    assert np.array_equal(lean.pressure, full.pressure)


def test_petsc_options_and_nonconvergence():
    N, L = 64, 1e-4
    fft = _fft(N)
    h = _random_surface(fft, L, q1fac=6)
    r = solve_contact(fft, L, h, Elastic(3e6), 0.0, 2e3, max_iterations=1, coarse=False)
    assert not r.converged and r.residual > 1e-8 and isinstance(r.reason, str)
    r = solve_contact(fft, L, h, Elastic(3e6), 0.0, 2e3, petsc_options=["-ksp_type gmres", "-ksp_gmres_restart 20"])
    assert r.converged


def test_eisenstat_walker_forcing_reaches_the_inner_solves(monkeypatch):
    """-snes_ksp_ew: every Newton step's inner Krylov solve runs at the rtol PETSc's Eisenstat-Walker
    forcing put on the outer (preonly) KSP, the first at rtol0, not at the inner KSP's own default."""
    from vecontact.solver import subset
    seen = []
    solve = subset.SubsetStep.solve

    def recorded(self):
        solve(self)
        seen.append((self.ksp.getTolerances()[0], self._outer.getTolerances()[0]))

    monkeypatch.setattr(subset.SubsetStep, "solve", recorded)
    fft = _fft(64)
    h = _random_surface(fft, 1e-4, q1fac=6)
    r = solve_contact(fft, 1e-4, h, Elastic(3e6), 0.0, 2e3, coarse=False,
                      petsc_options="-snes_ksp_ew -snes_ksp_ew_rtol0 0.25")
    assert r.converged, r.summary()
    assert len(seen) >= 3 and seen[0][0] == 0.25
    assert all(inner == outer for inner, outer in seen)      # the same float, passed on
    assert len({inner for inner, _ in seen}) >= 2             # the forcing moves from step to step


def test_bad_step_mode_is_refused():
    fft = _fft(32)
    h = _random_surface(fft, 1e-4, q1fac=4)
    with pytest.raises(ValueError, match="vc_contact_step"):
        solve_contact(fft, 1e-4, h, Elastic(3e6), 0.0, 2e3, petsc_options={"vc_contact_step": "sideways"})


def test_krylov_kernel_options_global_and_overridable():
    """PETSc's own VecMDot/VecMAXPY kernels by default (settings.PETSC_GLOBAL_DEFAULTS); a user's value
    from petsc_options is set globally (these options have no prefix) and gives the same solution."""
    from vecontact.solver.settings import PETSC_GLOBAL_DEFAULTS as GLOBAL_DEFAULTS
    from vecontact.solver.snes import petsc
    PETSc = petsc()
    opts = PETSc.Options()
    saved = {k: opts.getString(k) if opts.hasName(k) else None for k in GLOBAL_DEFAULTS}
    try:
        for k in GLOBAL_DEFAULTS:
            opts.delValue(k)
        N, L = 64, 1e-4
        fft = _fft(N)
        h = _random_surface(fft, L)
        mod = HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10, 0.5)
        a = solve_contact(fft, L, h, mod, 1.0, 2e5, store=(), coarse=False)
        assert all(opts.getString(k) == "0" for k in GLOBAL_DEFAULTS)
        b = solve_contact(fft, L, h, mod, 1.0, 2e5, store=(), coarse=False,
                          petsc_options={"vec_mdot_use_gemv": "1", "vec_maxpy_use_gemv": "true"})
        assert opts.getString("vec_mdot_use_gemv") == "1" and opts.getString("vec_maxpy_use_gemv") == "true"
        assert a.converged and b.converged and abs(a.area - b.area) <= 1.0 / N ** 2
        assert abs(a.mu - b.mu) <= 1e-6 * abs(a.mu)
    finally:
        for k, v in saved.items():
            opts.delValue(k)
            if v is not None:
                opts[k] = v


def _step_mode_problem():
    """The 64^2 problem of the step-mode tests: (fft, L, h, modulus, velocity)."""
    fft = _fft(64)
    L = 1e-4
    return fft, L, _random_surface(fft, L), HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10, 0.5), 1.0


def _solve_step_modes(problem, sigma0, **opts):
    """A converged single-grid solve of ``problem`` and the set of its Newton steps' modes."""
    fft, L, h, mod, v = problem
    r = solve_contact(fft, L, h, mod, v, sigma0, store=(), coarse=False, petsc_options=opts or None)
    assert r.converged, r.summary()
    return r, {m for _, m in r.diagnostics["step_modes"]}


def test_auto_step_mode_follows_contact_area():
    """contact_step auto: contact-set Newton steps while A/A0 <= SolverSettings.step_area (0.3 on this
    grid), free-set steps above; both give the same solution."""
    CONTACT_STEP_AREA = SolverSettings().contact_step_area
    problem = _step_mode_problem()
    N = problem[0].N
    low, modes_low = _solve_step_modes(problem, 300.0)
    high, modes_high = _solve_step_modes(problem, 1e4)
    assert low.area < CONTACT_STEP_AREA < high.area, (low.area, high.area)
    assert modes_low == {"contact"} and modes_high == {"free"}
    forced, modes_forced = _solve_step_modes(problem, 1e4, vc_contact_step_area=1.0)
    assert modes_forced == {"contact"}
    assert abs(forced.area - high.area) <= 1.0 / N ** 2 and abs(forced.mu - high.mu) <= 1e-6 * high.mu


def test_step_area_large_applies_by_the_operators_modulus_range():
    """The steps switch at contact_step_area_large (0 here: free-set steps at any area) where the
    modulus range, max|E(q_x v)|/min|E(q_x v)| of the solve's own operator, exceeds
    contact_step_modulus_large; the solution is the same either way."""
    from vecontact.solver.operator import ContactOperator
    problem = _step_mode_problem()
    fft, L, h, mod, v = problem
    N, sigma0 = fft.N, 300.0
    modulus_range = ContactOperator(fft, L, mod, v, sigma0, h).modulus_range()
    assert 1.5 < modulus_range < 1e3

    def run(modulus_large):
        return _solve_step_modes(problem, sigma0, vc_contact_step_area_large=0.0,
                                 vc_contact_step_modulus_large=modulus_large)

    below, modes_below = run(1.01 * modulus_range)
    above, modes_above = run(0.99 * modulus_range)
    assert modes_below == {"contact"} and modes_above == {"free"}
    assert abs(below.area - above.area) <= 1.0 / N ** 2 and abs(below.mu - above.mu) <= 1e-6 * above.mu


def test_step_area_small_applies_by_grid_size_and_modulus_range():
    """contact_step_area_small (1 here: contact-set steps at any area) where the solve's own operator has
    a modulus range max|E|/min|E| of at most contact_step_modulus_max on a grid of at least
    contact_step_min_n; the solution is the same either way."""
    from vecontact.solver.operator import ContactOperator

    problem = _step_mode_problem()
    fft, L, h, mod, v = problem
    N, sigma0 = fft.N, 1e4
    op = ContactOperator(fft, L, mod, v, sigma0, h)
    modulus_range, stiffness_range = op.modulus_range(), op.stiffness_range()
    # a viscoelastic range, well below the stiffness's (which holds the grid's q range too)
    assert 1.5 < modulus_range < stiffness_range / 10.0
    assert modulus_range < SolverSettings().contact_step_modulus_large

    def run(modulus_max, min_n):
        return _solve_step_modes(problem, sigma0, vc_contact_step_area_small=1.0,
                                 vc_contact_step_modulus_max=modulus_max, vc_contact_step_min_n=min_n)

    low, modes_low = run(1.01 * modulus_range, N)
    high, modes_high = run(0.99 * modulus_range, N)
    small, modes_small = run(1.01 * modulus_range, N + 1)
    assert high.area > SolverSettings().contact_step_area
    assert modes_low == {"contact"} and modes_high == {"free"} and modes_small == {"free"}
    assert abs(low.area - high.area) <= 1.0 / N ** 2 and abs(low.mu - high.mu) <= 1e-6 * high.mu


def test_modulus_range_is_the_rubbers_spread_over_the_grids_frequencies():
    """ContactOperator.modulus_range = max|E(q_x v)| / min|E(q_x v)| over the grid's q_x: 1 at rest and
    for an elastic solid; at speed, the same as numpy's on E's values at the grid's q_x (docs/
    conventions.md §4: omega = q_x v) and growing with v towards Einf / E0 (1000 here)."""
    from vecontact.solver.operator import ContactOperator
    fft, L, h, mod, v = _step_mode_problem()
    assert ContactOperator(fft, L, mod, 0.0, 1e4, h).modulus_range() == pytest.approx(1.0, abs=1e-12)
    assert ContactOperator(fft, L, Elastic(3e6, 0.5), 5.0, 1e4, h).modulus_range() == pytest.approx(1.0, abs=1e-12)
    qx = 2.0 * np.pi / L * np.fft.fftfreq(fft.N, 1.0 / fft.N)
    ranges = []
    for speed in (1e-3, 1.0, 1e3):
        E = np.abs(np.asarray(mod(qx * speed), dtype=complex))
        got = ContactOperator(fft, L, mod, speed, 1e4, h).modulus_range()
        assert got == pytest.approx(E.max() / E.min(), rel=1e-12)
        ranges.append(got)
    assert 1.0 < ranges[0] < ranges[1] < ranges[2] <= 1000.0 * (1.0 + 1e-9)


def test_ksp_options_reach_the_free_set_steps():
    """-ksp_* options reach the inner GMRES of the free-set steps (it has the solver's own prefix):
    -ksp_max_it 3 caps every step at 3 inner iterations, where the steps take more without it.  (No
    fallback: the capped steps do not converge in 6, and the VI method's steps are not free-set steps.)"""
    N, L = 64, 1e-4
    fft = _fft(N)
    h = _random_surface(fft, L)
    mod = HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10, 0.5)

    def run(**opts):
        r = solve_contact(fft, L, h, mod, 1.0, 1e4, store=(), coarse=False, max_iterations=6,
                          petsc_options=dict(vc_contact_step="free", vc_fallback="none", **opts))
        return r.linear_iterations, r.iterations

    free_lin, free_it = run()
    capped_lin, capped_it = run(ksp_max_it=3)
    assert free_lin > 3 * free_it, (free_lin, free_it)
    assert 0 < capped_lin <= 3 * capped_it, (capped_lin, capped_it)


def test_one_blas_thread_during_the_solve():
    """Under mpiexec numpy's OpenBLAS would run a thread per core in every rank (4.5x slower at 1024^2 on
    2 ranks): solve_contact holds the BLAS to one thread, whatever it had, and gives the threads back."""
    from threadpoolctl import threadpool_info, threadpool_limits

    def blas_threads():
        return [m["num_threads"] for m in threadpool_info() if m["user_api"] == "blas"]

    assert blas_threads(), "no BLAS found by threadpoolctl: the thread limit would do nothing"
    seen = []
    fft = _fft(64)
    h = _random_surface(fft, 1e-4)
    mod = HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10, 0.5)
    with threadpool_limits(limits=2, user_api="blas"):
        assert set(blas_threads()) == {2}
        r = solve_contact(fft, 1e-4, h, mod, 1.0, 2e5, monitor=lambda n, it, res: seen.append(blas_threads()))
        assert set(blas_threads()) == {2}        # given back
    assert r.converged and seen
    assert all(set(s) == {1} for s in seen)


def _huge_page_advice():
    """numpy's current madvise(MADV_HUGEPAGE) choice for new arrays (read by setting it back)."""
    advise = np._core.multiarray._set_madvise_hugepage
    now = advise(True)
    advise(now)
    return now


@pytest.mark.parametrize("caller", [True, False])
@pytest.mark.parametrize("how, during", [(None, False), ("option", True), ("settings", True)])
def test_huge_page_advice_during_the_solve(caller, how, during):
    """solve_contact allocates without numpy's huge-page advice by default (-vc_huge_pages off: its
    churn of large blocks costs a fault per 2 MiB page; RESULTS.md, "Huge pages"); with "on" it keeps
    the caller's choice.  Either way the caller's choice is back after the solve."""
    advise = np._core.multiarray._set_madvise_hugepage
    seen = []
    fft = _fft(32)
    h = _random_surface(fft, 1e-4)
    mod = HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10, 0.5)
    kw = {"option": dict(petsc_options={"vc_huge_pages": "on"}),
          "settings": dict(settings=SolverSettings(huge_pages="on"))}.get(how, {})
    before = advise(caller)
    try:
        r = solve_contact(fft, 1e-4, h, mod, 1.0, 2e5, monitor=lambda n, it, res: seen.append(_huge_page_advice()),
                          **kw)
        assert _huge_page_advice() is caller      # given back
    finally:
        advise(before)
    assert r.converged and seen
    assert set(seen) == {caller if during else False}


def test_huge_page_advice_is_restored_and_fft_buffers_ask_for_huge_pages():
    """core/pages.py sets numpy's advice for its block and restores the caller's, also on an exception;
    a SlabFFT made under advice off asks for huge pages for its own long-lived buffers and leaves the
    caller's advice as it was."""
    advise = np._core.multiarray._set_madvise_hugepage
    before = advise(True)
    try:
        for outer in (True, False):
            advise(outer)
            for inner in (True, False):
                with huge_page_advice(inner):
                    assert _huge_page_advice() is inner
                assert _huge_page_advice() is outer
            with pytest.raises(RuntimeError):
                with huge_page_advice(not outer):
                    raise RuntimeError
            assert _huge_page_advice() is outer
        seen = []
        real = advise

        def spy(flag):
            seen.append(flag)
            return real(flag)
        np._core.multiarray._set_madvise_hugepage = spy
        try:
            advise(False)
            SlabFFT(COMM, 16, planner="estimate", wisdom_file=False)
        finally:
            np._core.multiarray._set_madvise_hugepage = real
        assert seen[0] is True and seen[-1] is False       # on for its buffers, then the caller's off back
        assert _huge_page_advice() is False
    finally:
        advise(before)


def test_huge_pages_option_is_checked():
    assert SolverSettings().huge_pages == "off"
    with pytest.raises(ValueError, match="huge_pages"):
        SolverSettings().with_options({"vc_huge_pages": "yes"})


def test_a_solve_leaves_the_collectors_freeze_as_it_found_it():
    """snes.ncp_solve freezes what is alive for its duration (its end-of-level collection walks only
    what it made) and thaws it after; a caller's own frozen objects stay frozen (it then freezes
    nothing), and what the solve made is not left in the frozen generation."""
    import gc
    fft = _fft(64)
    L = 1e-4
    h = _random_surface(fft, L)
    modulus = HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10, 0.5)
    assert gc.get_freeze_count() == 0
    r = solve_contact(fft, L, h, modulus, 1.0, 5e4)
    assert r.converged, r.summary()
    assert gc.get_freeze_count() == 0       # thawed
    del r
    gc.freeze()
    try:
        mine = gc.get_freeze_count()
        r = solve_contact(fft, L, h, modulus, 1.0, 5e4)
        assert r.converged, r.summary()
        # not thawed (0), and nothing of the solve's frozen (more): some of the caller's may have died
        assert 0.9 * mine < gc.get_freeze_count() <= mine
    finally:
        gc.unfreeze()
