"""The edge correction of the contact-set preconditioner (vecontact/solver/edge.py), against dense
inverses of the compliance matrix built independently (tests/reference/dense.py)."""
import numpy as np
import pytest
from mpi4py import MPI

from reference.cases import L_PAPER, NU, small_spectrum
from reference.dense import compliance_matrix, multiplier, random_surface, stiffness_matrix

from vecontact.core.pfft import SlabFFT
from vecontact.physics.modulus import HavriliakNegami
from vecontact.solver.contactset import ContactSetStep
from vecontact.solver.edge import EdgeCorrection
from vecontact.solver.operator import ContactOperator
from vecontact.solver.settings import SolverSettings
from vecontact.solver.snes import petsc

N = 24


def _case(v=1.0, area=0.25, seed=4):
    """A 24^2 paper-like surface under HN at ``v`` (1 m/s: a strongly non-symmetric kernel), its
    operator and a contact set of patches (the highest ``area`` of the surface)."""
    mod = HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10, NU)
    h = random_surface(N, L_PAPER, small_spectrum(N), seed=seed)
    fft = SlabFFT(MPI.COMM_SELF, N, planner="estimate", wisdom_file=False)
    op = ContactOperator(fft, L_PAPER, mod, v, 1e5, h)
    act = h > np.quantile(h, 1.0 - area)
    return mod, h, op, act


def _dense_rows(mod, op, act, w, drop, v=1.0, rows="inverse"):
    """{flat point: {flat point: coefficient}} of the edge term, from the dense nondimensional
    compliance (or stiffness) matrix: for each contact point with a free point in its window W, the
    centre row of inv(c on W and C) minus that of inv(c on W) ("inverse"), or of -m_CF inv(m_FF) m_FC
    with F the window's free points and C its contact points ("schur"); entries below ``drop`` x the
    row's largest dropped."""
    Mq = multiplier(N, L_PAPER, mod, NU, v)
    K = compliance_matrix(Mq) * (op.sigma0 / op.ell)
    S = stiffness_matrix(Mq) * (op.ell / op.sigma0)
    out = {}
    for i in np.flatnonzero(act.ravel()):
        r, c = divmod(i, N)
        win = [((r + a) % N) * N + (c + b) % N for a in range(-w, w + 1) for b in range(-w, w + 1)]
        sub = [j for j in win if act.flat[j]]
        if len(sub) == len(win):
            continue
        if rows == "inverse":
            local = np.linalg.inv(K[np.ix_(sub, sub)])[sub.index(i)]
            whole = np.linalg.inv(K[np.ix_(win, win)])[len(win) // 2]
            row = local - whole[[win.index(j) for j in sub]]
        else:
            free = [j for j in win if not act.flat[j]]
            row = -S[i, free] @ np.linalg.solve(S[np.ix_(free, free)], S[np.ix_(free, sub)])
        row[np.abs(row) < drop * np.abs(row).max()] = 0.0
        out[i] = {j: x for j, x in zip(sub, row) if x != 0.0}
    return out


@pytest.mark.parametrize("w, drop, rows", [(2, 0.0, "inverse"), (2, 0.2, "inverse"), (1, 0.0, "inverse"),
                                           (3, 0.2, "inverse"), (2, 0.0, "schur"), (2, 0.2, "schur"),
                                           (1, 0.0, "schur"), (3, 0.2, "schur")])
def test_edge_rows_are_the_local_inverses(w, drop, rows):
    """Every row of the term, as ``apply`` gives it (column j: the term of the unit vector e_j, so the
    periodic halo is in it), against the dense inverses or Schur complements (rtol 1e-9 of the row's
    largest entry: the windows' matrices are at most 49 x 49 and well conditioned, the kernels differ
    from the dense ones by FFT rounding only); interior points have no row; the drop leaves what the
    rule keeps."""
    mod, h, op, act = _case()
    idx = np.flatnonzero(act.ravel())
    assert act[:w].any() and act[-w:].any() and act[:, :w].any() and act[:, -w:].any()   # windows wrap
    ec = EdgeCorrection(op, w, drop, rows=rows)
    ec.build(act, idx)
    G = np.column_stack([ec.apply(e) for e in np.eye(idx.size)])
    ref = _dense_rows(mod, op, act, w, drop, rows=rows)
    assert 0 < len(ref) <= idx.size and (len(ref) < idx.size or w == 3)    # 7 x 7: every point is an edge one
    assert ec.S.shape[0] == len(ref)       # S keeps a row for each edge point only
    for k, i in enumerate(idx):
        got = {int(idx[j]): G[k, j] for j in np.flatnonzero(G[k])}
        want = ref.get(int(i), {})
        if not want:
            assert not got, i
            continue
        scale = max(abs(x) for x in want.values())
        # entries near the drop threshold may fall either side of it by rounding
        close = {j for j, x in want.items() if abs(abs(x) - drop * scale) <= 1e-9 * scale}
        assert set(got) ^ set(want) <= close, (i, sorted(got), sorted(want))
        for j in set(got) & set(want):
            assert abs(got[j] - want[j]) <= 1e-9 * scale, (i, j, got[j], want[j])


@pytest.mark.parametrize("w", [1, 2, 3])
def test_mask_rows_by_either_system(w):
    """Each window mask's row is solved on its contact points (few in contact) or through the Schur
    complement on its free points (many): both against the row of one direct K x K solve of c on the
    window's contact points (identity on its free ones), for masks of every contact count (1e-11 of
    the row's largest entry: K <= 49 and c_W well conditioned, so the two eliminations differ by
    rounding only)."""
    mod, h, op, act = _case()
    ec = EdgeCorrection(op, w, 0.0)
    cW, M = ec._kernel_table()
    K = cW.shape[0]
    rng = np.random.default_rng(5)
    mask = np.zeros((3 * (K - 1), K), dtype=bool)
    for i, p in enumerate(np.repeat(np.arange(1, K), 3)):   # p contact points, the centre one of them
        others = rng.choice(np.delete(np.arange(K), K // 2), p - 1, replace=False)
        mask[i, np.append(others, K // 2)] = True
    got = ec._solve_masks(mask)
    for m, row in zip(mask, got):
        A = np.where(np.outer(m, m), cW.T, 0.0) + np.diag(~m)
        want = (np.linalg.solve(A, np.eye(K)[K // 2]) - M[K // 2]) * m
        assert np.abs(row - want).max() <= 1e-11 * np.abs(want).max(), (m.sum(), row, want)


def _preconditioner_floor(op, act, w, rows):
    """The smallest eigenvalue of the symmetric part of a contact-set step's preconditioner B = P (m_CC
    + edge term) P (dense, from its products with the zero-mean unit vectors) on the zero-mean vectors
    of the set: B is positive definite there when it is positive."""
    st = SolverSettings(edge_window=w, edge_window_large=w, edge_window_high=w,
                        edge_schur_modulus_min=0.0 if rows == "schur" else 1e300)
    step = ContactSetStep(op, op.kappa, petsc(), "edgetest_", st)
    n = int(np.count_nonzero(act))
    try:
        step.set_active(act, n)
        assert step.edge.w == w and step.edge.rows == rows
        B = np.zeros((n, n))
        apply = step.preconditioner().matvec
        for j, e in enumerate(np.eye(n) - 1.0 / n):
            apply(e, B[:, j])
    finally:
        step.release()
    Q = np.linalg.qr(np.eye(n) - 1.0 / n)[0][:, :n - 1]          # an orthonormal basis of the zero-mean vectors
    return np.linalg.eigvalsh(Q.T @ (B + B.T) @ Q / 2.0)[0]


def test_schur_rows_keep_the_preconditioner_definite():
    """At fast sliding (v = 30 m/s on a 32^2 grid: a strongly non-symmetric kernel) the local inverses of
    7 x 7 and 3 x 3 windows make the preconditioner indefinite (the contact-set steps then stall), and
    the Schur rows keep it positive definite at every width, as m_CC alone is (its symmetric part is
    a principal block of m's, whose symbol |q| Re E(q_x v) / 2(1 - nu^2) is positive).  The floors
    are O(1) against m's diagonal of O(100): far from zero on either side of it."""
    global N
    old, N = N, 32
    try:
        mod, h, op, act = _case(v=30.0, area=0.3)
    finally:
        N = old
    assert op.modulus_range() < SolverSettings().edge_schur_modulus_min
    floors = {(w, rows): _preconditioner_floor(op, act, w, rows) for w in (1, 2, 3) for rows in EdgeCorrection.ROWS}
    assert floors[(1, "inverse")] < -0.1 and floors[(3, "inverse")] < -0.1, floors
    assert min(floors[(w, "schur")] for w in (1, 2, 3)) > 0.5, floors


def test_edge_rows_by_modulus_range():
    """The local inverses up to edge_schur_modulus_min, the Schur rows above it, with edge_window's half
    width whatever the stiffness's range; 0 puts the Schur rows everywhere."""
    st = SolverSettings()
    m = st.edge_schur_modulus_min
    assert m == 300.0
    assert st.edge_rows(m) == "inverse" and st.edge_rows(1.0) == "inverse"
    assert st.edge_rows(np.nextafter(m, np.inf)) == "schur"
    r = 10.0 * st.edge_high_range_min
    assert st.edge_half_width(m, 0.05, r, 4096) == st.edge_window_high
    assert st.edge_half_width(np.nextafter(m, np.inf), 0.05, r, 4096) == st.edge_window
    assert SolverSettings(edge_schur_modulus_min=0.0).edge_rows(1.0) == "schur"
    # the paper's rubber keeps the local inverses on every grid of its study and benchmark: its largest
    # range there is 4096^2 at 10 m/s (252.6), the ratio of |E| at the grid's largest and smallest q_x
    mod = HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10, NU)
    E = np.abs(mod(2.0 * np.pi * np.fft.fftfreq(4096, L_PAPER / 4096) * 10.0))
    assert 250.0 < E.max() / E.min() < m


def test_a_broad_transition_solves_with_the_schur_rows():
    """A rubber with a broad glass transition (E_inf / E_0 = 1e4) sliding at 30 m/s on a 64^2 grid
    (modulus range above edge_schur_modulus_min): the default's contact-set steps take the Schur rows
    and the solve converges within 1.5x the FFT pairs of one without the edge term (784 against 1060
    measured; the local inverses took 20596 pairs and 31 Newton iterations; RESULTS.md, "Edge rows
    from the stiffness")."""
    from reference.dense import random_surface as surface
    from vecontact.solver import solve_contact
    n = 64
    h = surface(n, L_PAPER, small_spectrum(n), seed=4)
    mod = HavriliakNegami(3e6, 3e10, 0.5, 0.5, 1e-10, NU)
    fft = SlabFFT(MPI.COMM_SELF, n, planner="estimate", wisdom_file=False)
    assert ContactOperator(fft, L_PAPER, mod, 30.0, 1e6, h).modulus_range() > SolverSettings().edge_schur_modulus_min
    runs = [solve_contact(fft, L_PAPER, h, mod, 30.0, 1e6, tolerance=1e-8, store=(), petsc_options=opts)
            for opts in (None, ["-vc_edge_window 0"])]
    assert all(r.converged for r in runs)
    assert abs(runs[0].area - runs[1].area) * n * n <= 1
    assert runs[0].fft_pairs <= 1.5 * runs[1].fft_pairs, (runs[0].fft_pairs, runs[1].fft_pairs)


def test_a_stalled_solve_starts_again_without_the_edge_term():
    """A rubber with a sharp glass transition (Havriliak-Negami alpha = beta = 0.8, loss angle up to 68
    deg) at 1 mm/s on a 64^2 grid, 36 % in contact: with the edge term the contact-set steps stall (no
    convergence in 100 Newton iterations, measured), so after edge_newton_max iterations, or sooner once
    edge_stall pass without a new lowest measure (22 here, measured), the solve
    starts again from its first iterate without the term, converges, reports the first attempt in
    diagnostics["edge_retry"] and counts both attempts; its contact area is that of a solve without the
    term from the start (one grid point), and a solve that converges in time is never retried."""
    from reference.dense import random_surface as surface
    from vecontact.solver import solve_contact
    n = 64
    h = surface(n, L_PAPER, small_spectrum(n), seed=4)
    mod = HavriliakNegami(3e6, 3e9, 0.8, 0.8, 1e-6, NU)
    fft = SlabFFT(MPI.COMM_SELF, n, planner="estimate", wisdom_file=False)
    cap = SolverSettings().edge_newton_max
    r, plain = (solve_contact(fft, L_PAPER, h, mod, 0.001, 3e4, tolerance=1e-8, store=(), petsc_options=opts)
                for opts in (None, ["-vc_edge_window 0"]))
    assert r.converged and plain.converged
    retry = r.diagnostics["edge_retry"]
    s = SolverSettings()
    assert retry is not None and s.edge_stall < retry["iterations"] <= cap and retry["residual"] > 1e-8
    assert r.iterations == retry["iterations"] + plain.iterations and r.fft_pairs > plain.fft_pairs
    assert abs(r.area - plain.area) * n * n <= 1
    assert plain.diagnostics["edge_retry"] is None
    quick = solve_contact(fft, L_PAPER, h, mod, 0.001, 1e4, tolerance=1e-8, store=())
    assert quick.converged and quick.iterations < cap and quick.diagnostics["edge_retry"] is None


def test_steps_at_their_cap_start_the_solve_again_and_the_finer_grids_without_the_term():
    """The sharp rubber at 1 cm/s on a 128^2 grid, 4 % in contact: on the 64^2 coarse grid the
    contact-set steps with the edge term run to the whole ksp_max_it step after step (the stall's mark;
    measured: 400, 400, 400 at its seventh to ninth steps). After edge_capped_max such steps in a row,
    long before edge_newton_max, that grid starts again without the term, and so does the finer one:
    from there on the solve is bit for bit the one without the term from the start, plus the first
    attempt's pairs. With the rule off (and fallback_coarse, which would hand that grid and the finer
    one to the fallback), the coarse grid runs on to coarse_max_it, and the solve costs several times
    the pairs. The fine grid then starts from that grid's wandering iterate: whether it stalls too
    depends on the FFTs' rounding (from empty wisdom, conftest.py, it does and starts again at
    edge_newton_max; with this machine's wisdom loaded it converged in 20 iterations with the term)."""
    from vecontact.solver import solve_contact
    n = 128
    h = random_surface(n, L_PAPER, small_spectrum(n), seed=4)
    mod = HavriliakNegami(3e6, 3e9, 0.8, 0.8, 1e-6, NU)
    fft = SlabFFT(MPI.COMM_SELF, n, planner="estimate", wisdom_file=False)
    s = SolverSettings()
    r, plain = (solve_contact(fft, L_PAPER, h, mod, 0.01, 3e4, tolerance=1e-8, store=("pressure",),
                              petsc_options=opts) for opts in (None, ["-vc_edge_window 0"]))
    assert r.converged and plain.converged
    coarse, fine = r.diagnostics["levels"]
    assert coarse["N"] == 64 and s.edge_capped_max < coarse["edge_retry"]["iterations"] < s.edge_newton_max
    assert fine["edge_retry"] is None and r.diagnostics["edge_retry"] is None
    assert coarse["iterations"] == coarse["edge_retry"]["iterations"] + plain.diagnostics["levels"][0]["iterations"]
    assert np.array_equal(r.pressure, plain.pressure) and r.iterations == plain.iterations
    assert r.fft_pairs_by_level[n] == plain.fft_pairs_by_level[n]
    assert r.fft_pairs_by_level[64] > plain.fft_pairs_by_level[64]
    off = solve_contact(fft, L_PAPER, h, mod, 0.01, 3e4, tolerance=1e-8, store=(),
                        petsc_options=["-vc_edge_capped_max 0", "-vc_fallback_coarse off"])
    assert off.diagnostics["levels"][0]["iterations"] == s.coarse_max_it
    # if the fine grid stalls too, it starts again without the term by the count or, sooner, by edge_stall
    retry = off.diagnostics["edge_retry"]
    assert off.converged and (retry is None or s.edge_stall < retry["iterations"] <= s.edge_newton_max)
    assert off.fft_pairs > 3 * r.fft_pairs


def test_only_the_finest_grid_starts_again_by_its_iteration_count():
    """edge_newton_max counts the finest grid's Newton iterations only: a coarse solve ends at
    coarse_max_it anyway, and the study's coarse grids wander up to 49 iterations without a stall
    (4096^2, 10 m/s, 19 %: its 512^2 grid). The paper-like rubber at 10 m/s on 128^2 with the count
    lowered to 4: the 64^2 grid runs its 12 iterations with the term, the 128^2 one starts again after
    4 and reaches the same contact set."""
    from vecontact.solver import solve_contact
    n = 128
    h = random_surface(n, L_PAPER, small_spectrum(n), seed=4)
    mod = HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10, NU)
    fft = SlabFFT(MPI.COMM_SELF, n, planner="estimate", wisdom_file=False)
    r, low = (solve_contact(fft, L_PAPER, h, mod, 10.0, 1e5, tolerance=1e-8, store=(), petsc_options=opts)
              for opts in (None, ["-vc_edge_newton_max 4", "-vc_edge_capped_max 0"]))
    assert r.converged and low.converged
    (c0, f0), (c1, f1) = r.diagnostics["levels"], low.diagnostics["levels"]
    assert c1["iterations"] == c0["iterations"] > 4 and c1["edge_retry"] is None
    assert f0["edge_retry"] is None and f0["iterations"] > 4 and f1["edge_retry"]["iterations"] == 4
    assert abs(r.area - low.area) * n * n <= 1


def test_edge_term_of_a_float32_vector():
    """A float32 C-vector (the float32 preconditioner's input) gives the term of its float64 value."""
    mod, h, op, act = _case()
    idx = np.flatnonzero(act.ravel())
    ec = EdgeCorrection(op, 2, 0.2)
    ec.build(act, idx)
    x = np.random.default_rng(1).standard_normal(idx.size).astype(np.float32)
    assert np.array_equal(ec.apply(x), ec.apply(x.astype(float)))


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_edge_term_added_in_place_is_the_product(dtype):
    """add_to (the preconditioner's path: no new array a call) adds exactly np.add(y, apply(x)), the
    float64 term rounded to y's dtype, twice in a row (its kept product starts from zero each call)."""
    mod, h, op, act = _case()
    idx = np.flatnonzero(act.ravel())
    ec = EdgeCorrection(op, 2, 0.2)
    ec.build(act, idx)
    rng = np.random.default_rng(3)
    for _ in range(2):
        x = rng.standard_normal(idx.size).astype(dtype)
        y = rng.standard_normal(idx.size).astype(dtype)
        want = np.add(y, ec.apply(x), out=y.copy(), casting="same_kind")
        ec.add_to(x, y)
        assert np.array_equal(y, want)
        assert np.count_nonzero(ec.apply(x)) > idx.size // 20       # a term that changes y


def test_no_edge_in_full_contact():
    """All points in contact: no edge, the term is zero."""
    mod, h, op, act = _case()
    act = np.ones((N, N), dtype=bool)
    ec = EdgeCorrection(op, 2, 0.2)
    ec.build(act, np.arange(N * N))
    assert ec.S.nnz == 0
    assert not ec.apply(np.ones(N * N)).any()


def test_no_term_where_the_window_wraps():
    """On a 4^2 grid a 5 x 5 window would hold a point twice: no term (the step runs without it)."""
    fft = SlabFFT(MPI.COMM_SELF, 4, planner="estimate", wisdom_file=False)
    h = np.random.default_rng(9).standard_normal((4, 4)) * 1e-8
    op = ContactOperator(fft, L_PAPER, HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10, NU), 1.0, 1e5, h)
    act = h > 0
    ec = EdgeCorrection(op, 2, 0.2)
    ec.build(act, np.flatnonzero(act.ravel()))
    assert not ec.usable and ec.apply(np.ones(int(act.sum()))) is None
    assert EdgeCorrection(op, 1, 0.2).usable
    with pytest.raises(ValueError, match="half width 4"):
        EdgeCorrection(op, 4, 0.2)


def _step_solve(settings, area, v):
    """(inner iterations, the Newton update, the half width of the step's edge term or 0) of one
    contact-set step to rtol 1e-10 from zero, on _case's set and a fixed right-hand side."""
    mod, h, op, act = _case(v=v, area=area)
    step = ContactSetStep(op, op.kappa, petsc(), "edgetest_", settings)
    PETSc = petsc()
    r = PETSc.Vec().createSeq(N * N)
    y = r.duplicate()
    try:
        step.set_active(act, int(np.count_nonzero(act)))
        step.set_tolerances(1e-10, 0.0, 500)
        r.getArray()[:] = np.random.default_rng(2).standard_normal(N * N)
        step.apply(None, r, y)
        assert step.ksp.getConvergedReason() > 0
        return step.iterations, y.getArray().copy(), 0 if step.edge is None else step.edge.w
    finally:
        step.release()
        r.destroy()
        y.destroy()


def _inner_iterations(window, area, v):
    its, _, w = _step_solve(SolverSettings(edge_window=window, edge_window_large=window), area, v)
    assert w == window
    return its


@pytest.mark.parametrize("area, v", [(0.05, 10.0), (0.25, 1.0)])
def test_edge_correction_cuts_the_inner_iterations(area, v):
    """A contact-set step to rtol 1e-10 needs fewer inner iterations with the term than without
    (deterministic counts: FGMRES from zero on the same right-hand side)."""
    with_edge, without = _inner_iterations(2, area, v), _inner_iterations(0, area, v)
    assert with_edge < without, (with_edge, without)


def test_an_unchanged_set_keeps_its_term():
    """The exact Newton steps hand build() the last step's set again: S stands (the same object, no
    rebuild).  Any other set is built afresh: one point changed gives the term of a fresh
    EdgeCorrection on that set, and going back gives the first set's term again."""
    mod, h, op, act = _case()
    ec = EdgeCorrection(op, 2, 0.2)
    ec.build(act, np.flatnonzero(act.ravel()))
    S = ec.S
    ec.build(act.copy(), np.flatnonzero(act.ravel()))
    assert ec.S is S
    changed = act.copy()
    changed.flat[np.flatnonzero(~act.ravel())[0]] = True
    for a in (changed, act):
        ec.build(a, np.flatnonzero(a.ravel()))
        fresh = EdgeCorrection(op, 2, 0.2)
        fresh.build(a, np.flatnonzero(a.ravel()))
        assert ec.S is not S and ec.S.shape == fresh.S.shape
        assert (ec.S != fresh.S).nnz == 0


def test_edge_half_width_by_area_and_modulus_range():
    """edge_window_large from edge_large_area of the grid up, at a modulus range up to
    edge_large_modulus_max; edge_window elsewhere; no term at all when edge_window is 0."""
    st = SolverSettings()
    lo, hi = st.edge_large_modulus_max, 2.0 * st.edge_large_modulus_max
    assert (st.edge_window, st.edge_window_large) == (2, 1)
    assert st.edge_half_width(lo, st.edge_large_area) == 1
    assert st.edge_half_width(1.0, 0.9) == 1
    assert st.edge_half_width(lo, np.nextafter(st.edge_large_area, 0.0)) == 2
    assert st.edge_half_width(np.nextafter(lo, np.inf), 0.9) == 2
    assert st.edge_half_width(hi, 0.05) == 2
    assert SolverSettings(edge_window=0).edge_half_width(1.0, 0.9) == 0
    assert SolverSettings(edge_window_large=0).edge_half_width(1.0, 0.9) == 0
    assert SolverSettings(edge_large_area=1.5).edge_half_width(1.0, 1.0) == 2


def test_edge_half_width_by_stiffness_range():
    """edge_window_high from a stiffness range of edge_high_range_min up (fast sliding on fine grids) on
    grids from edge_high_min_n up, unless the large-set rule of slow sliding applies; edge_window below
    either; nothing when edge_window is 0."""
    st = SolverSettings()
    r, n = st.edge_high_range_min, st.edge_high_min_n
    assert (st.edge_window_high, r, n) == (3, 1.5e5, 2048)
    fast = 2.0 * st.edge_large_modulus_max
    assert st.edge_half_width(fast, 0.05, r, n) == 3
    assert st.edge_half_width(fast, 0.3, 10.0 * r, 4096) == 3
    assert st.edge_half_width(fast, 0.05, np.nextafter(r, 0.0), n) == 2
    assert st.edge_half_width(fast, 0.05, 10.0 * r, n // 2) == 2      # 1024^2: 5 x 5 at any range
    assert st.edge_half_width(fast, 0.05) == 2                       # no stiffness range or grid given
    assert st.edge_half_width(1.0, 0.9, 10.0 * r, n) == 1             # slow sliding, large set
    assert st.edge_half_width(1.0, 0.05, 10.0 * r, n) == 3
    assert SolverSettings(edge_window=0).edge_half_width(fast, 0.05, r, n) == 0
    assert SolverSettings(edge_window_high=2).edge_half_width(fast, 0.05, r, n) == 2


def test_the_step_takes_the_high_window_above_the_range():
    """At fast sliding a contact-set step builds edge_window_high's term where the grid's stiffness
    range reaches edge_high_range_min and its N edge_high_min_n (both lowered here to this 24^2 grid's),
    bit for bit the step whose windows are all of that width, and edge_window's just below either."""
    area, v = 0.05, 10.0
    op = _case(v=v, area=area)[2]
    rng, n = op.stiffness_range(), op.fft.N
    its, y, w = _step_solve(SolverSettings(edge_high_range_min=rng, edge_high_min_n=n), area, v)
    assert w == 3
    its_3, y_3, _ = _step_solve(SolverSettings(edge_window=3), area, v)
    assert its == its_3 and np.array_equal(y, y_3)
    assert _step_solve(SolverSettings(edge_high_range_min=np.nextafter(rng, np.inf), edge_high_min_n=n),
                       area, v)[2] == 2
    assert _step_solve(SolverSettings(edge_high_range_min=rng, edge_high_min_n=n + 1), area, v)[2] == 2
    assert _step_solve(SolverSettings(), area, v)[2] == 2


@pytest.mark.parametrize("area, v, expect", [(0.25, 0.01, 1), (0.05, 0.01, 2)])
def test_the_step_takes_the_window_of_its_set(area, v, expect):
    """A contact-set step builds the term of the half width its set calls for (slow sliding: a low
    modulus range), and solves with exactly that term: the same iterations and update, bit for bit,
    as a step whose windows are all of that width; and the same update, to the inner tolerance, as a
    step with the other width."""
    mod, h, op, act = _case(v=v, area=area)
    assert op.modulus_range() <= SolverSettings().edge_large_modulus_max
    its, y, w = _step_solve(SolverSettings(), area, v)
    assert w == expect
    its_w, y_w, _ = _step_solve(SolverSettings(edge_window=expect, edge_window_large=expect), area, v)
    assert its == its_w and np.array_equal(y, y_w)
    other = 3 - expect
    _, y_o, w_o = _step_solve(SolverSettings(edge_window=other, edge_window_large=other), area, v)
    assert w_o == other
    # both solved to rtol 1e-10: apart by that times a margin of 100 for the conditioning of c_CC
    # (5e-11 and 2e-11 measured)
    assert np.max(np.abs(y - y_o)) <= 1e-8 * np.max(np.abs(y))


def test_a_step_changes_width_with_its_set():
    """One step object given a large set, then a small one (as a solve whose set shrinks past
    edge_large_area): the small set gets the wider term, the same as a fresh EdgeCorrection's on it,
    and the step's update is a fresh step's on that set, bit for bit."""
    # the fresh step first: two steps alive at once would share the options prefix's defaults
    _, y_fresh, w_fresh = _step_solve(SolverSettings(), 0.05, 0.01)
    mod, h, op, big = _case(v=0.01, area=0.25)
    small = _case(v=0.01, area=0.05)[3]
    PETSc = petsc()
    step = ContactSetStep(op, op.kappa, PETSc, "edgetest_", SolverSettings())
    r = PETSc.Vec().createSeq(N * N)
    y = r.duplicate()
    try:
        r.getArray()[:] = np.random.default_rng(2).standard_normal(N * N)
        widths = []
        for act in (big, small):
            step.set_active(act, int(np.count_nonzero(act)))
            widths.append(step.edge.w)
            step.set_tolerances(1e-10, 0.0, 500)
            step.apply(None, r, y)
        assert widths == [1, 2] and w_fresh == 2
        fresh = EdgeCorrection(op, 2, SolverSettings().edge_drop)
        fresh.build(small, np.flatnonzero(small.ravel()))
        assert step.edge.S.shape == fresh.S.shape and (step.edge.S != fresh.S).nnz == 0
        assert np.array_equal(y.getArray(), y_fresh)
    finally:
        step.release()
        r.destroy()
        y.destroy()
