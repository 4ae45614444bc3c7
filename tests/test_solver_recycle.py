"""Directions carried across the contact-set steps whose set changed (vecontact/solver/recycle.py).

* GCRO in SingleGMRES (``carried``) against dense solves: the residual it stops on is the true one, it
  needs fewer iterations with the directions of a nearby solve, and its Arnoldi relation gains the
  carried part, A Z = V G + C E;
* the map of carried directions to a new contact set against the dense compliance matrix
  (tests/reference/dense.py): the directions restricted and made zero-sum, their products to float32
  rounding; the orthonormal basis; the directions kept after a solve;
* CarriedDirections' order for an exact step: the directions, then the residual once;
* the solver on a paper surface at 10 m/s, the map on against off (carry_map_cost 0): the same answer
  to the solver's tolerance, fewer iterations and FFT pairs; every set of directions a step keeps is
  used by the next (none is built for a step that does not map it).

The paper case's modulus range at 256^2 (82) is under carry_modulus_min's default: ``CARRY_OPEN`` lets it
carry (test_solver_carry.py tests that gate).
"""
import numpy as np
import pytest
from mpi4py import MPI

from reference.cases import CARRY_OPEN, L_PAPER, NU, paper_contact_solve, small_spectrum
from reference.dense import compliance_matrix, multiplier, random_surface
from reference.krylov import allsum as _allsum, operators as _ops, system as _system

from vecontact.core.pfft import SlabFFT
from vecontact.physics.modulus import HavriliakNegami
from vecontact.solver.carry import CarriedDirections
from vecontact.solver.operator import ContactOperator
from vecontact.solver.recycle import CarriedSpace, ComplianceKernel, _Basis
from vecontact.solver.single import SingleGMRES

N = 24


def _carried_basis(A, U):
    """U and C = A U, orthonormalised together (float32 C, as recycle.py hands them)."""
    Q, R = np.linalg.qr(A @ U.T)
    T = np.linalg.inv(R)
    return _Basis(None, (U.T @ T).T.copy(), Q.T.astype(np.float32))


@pytest.mark.parametrize("restart", [200, 5])
def test_gcro_true_residual_and_fewer_iterations(restart):
    """restart 5: GCRO restarts (its residual recomputed and projected again); plain GMRES runs unrestarted."""
    A, B, b = _system(240, 7)
    first = SingleGMRES(b.size, 200, _allsum, flexible=True, work=np.float64)
    first.solve(*_ops(A, B), b, np.empty(b.size), 1e-4, 0.0, 500)
    k = first.arnoldi[0]
    carried = _carried_basis(A, first.Z[:k].astype(np.float64))
    b2 = b + 0.3 * np.random.default_rng(1).standard_normal(b.size)      # a nearby right-hand side
    nb = np.linalg.norm(b2)
    its = {}
    for name, c in (("plain", None), ("gcro", carried)):
        gm = SingleGMRES(b.size, restart if c is not None else 200, _allsum, flexible=True, work=np.float64)
        x = np.empty(b.size)
        its[name], est = gm.solve(*_ops(A, B), b2, x, 1e-3, 0.0, 500, carried=c)
        true = np.linalg.norm(b2 - A @ x)
        # float32 basis and float32 C: the estimate tracks the true residual to ~1e-6 |b|
        assert est <= 1e-3 * nb and true <= 1e-3 * nb * 1.05 + 2e-6 * nb, (name, est, true)
        if c is not None and restart == 200:
            kk, G = gm.arnoldi
            AZ = gm.Z[:kk] @ A.T
            VGCE = G.T @ gm.V[:kk + 1].astype(np.float64) + gm.projected.T @ c.C.astype(np.float64)
            for j in range(kk):
                assert np.linalg.norm(AZ[j] - VGCE[j]) <= 1e-5 * np.linalg.norm(AZ[j]), j
    assert its["gcro"] < 0.8 * its["plain"], its


def test_gcro_monitor_trial_is_the_answer():
    """With carried directions (an exact step's GCRO start, carry.py) the monitor's trial solution
    after k iterations holds the carried part too: bit for bit what the solve returns when stopped
    there (restart 5: across restarts), and its true residual matches the estimate."""
    A, B, b = _system(240, 7)
    first = SingleGMRES(b.size, 200, _allsum, flexible=True, work=np.float64)
    first.solve(*_ops(A, B), b, np.empty(b.size), 1e-4, 0.0, 500)
    carried = _carried_basis(A, first.Z[:first.arnoldi[0]].astype(np.float64))
    b2 = b + 0.3 * np.random.default_rng(1).standard_normal(b.size)
    trials, ests = [], []

    def monitor(its, res, build):
        if its == 7:
            trials.append(np.empty(b.size))
            build(trials[-1])
            ests.append(res)
            return True
        return False
    x = np.empty(b.size)
    its, est = SingleGMRES(b.size, 5, _allsum, flexible=True, work=np.float64).solve(
        *_ops(A, B), b2, x, 1e-12, 0.0, 500, carried=carried, monitor=monitor)
    assert its == 7 and np.array_equal(trials[0], x) and est == ests[0]
    true = np.linalg.norm(b2 - A @ x)
    assert abs(true - est) <= 1e-5 * np.linalg.norm(b2) and true < 0.5 * np.linalg.norm(b2)


def test_gcro_starts_done_when_the_carried_space_holds_b():
    A, B, b = _system(120, 3)
    U = np.linalg.solve(A, b)[None, :]                  # A U = b: the carried space solves it
    gm = SingleGMRES(b.size, 50, _allsum, flexible=True, work=np.float64)
    x = np.empty(b.size)
    its, est = gm.solve(*_ops(A, B), b, x, 1e-4, 0.0, 100, min_it=0, carried=_carried_basis(A, U))
    assert its == 0 and np.linalg.norm(b - A @ x) <= 1e-6 * np.linalg.norm(b)


def _grid_case(v=1.0, seed=4):
    mod = HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10, NU)
    h = random_surface(N, L_PAPER, small_spectrum(N), seed=seed)
    fft = SlabFFT(MPI.COMM_SELF, N, planner="estimate", wisdom_file=False)
    op = ContactOperator(fft, L_PAPER, mod, v, 1e5, h)
    K = compliance_matrix(multiplier(N, L_PAPER, mod, NU, v)) * (op.sigma0 / op.ell)
    return fft, op, h, K


def test_map_against_the_dense_compliance():
    """Sets of patches that wrap around the grid; 9 points left, 7 joined (and the product of the
    map's mean term, (c 1_C)_C, from the dense matrix too).  float32 products: 1e-6 of their size."""
    fft, op, h, K = _grid_case()
    rng = np.random.default_rng(2)
    old_set = h.ravel() > np.quantile(h, 0.7)
    new_set = old_set.copy()
    new_set[rng.choice(np.flatnonzero(old_set), 9, replace=False)] = False
    new_set[rng.choice(np.flatnonzero(~old_set), 7, replace=False)] = True
    old, new = np.flatnonzero(old_set), np.flatnonzero(new_set)
    U = rng.standard_normal((5, old.size))
    U -= U.mean(axis=1, keepdims=True)
    W = (K[np.ix_(old, old)] @ U.T).T.astype(np.float32)           # raw products on the old set
    space = CarriedSpace(old, U, W)
    assert CarriedSpace.changed(fft, old, new) == 16
    ones_product = K[np.ix_(new, new)] @ np.ones(new.size)
    got = space.mapped(fft, new, new.size, ComplianceKernel(op), ones_product)
    # the reference: the directions on the common points, zero on the joined, less their mean
    ref = np.zeros((5, K.shape[0]))
    ref[:, old] = U
    ref[:, ~new_set] = 0.0
    ref = ref[:, new]
    ref -= ref.mean(axis=1, keepdims=True)
    assert np.allclose(got.U, ref, rtol=0, atol=1e-12)
    want = (K[np.ix_(new, new)] @ ref.T).T
    for g, w in zip(got.W, want):
        assert np.linalg.norm(g - w) <= 1e-6 * np.linalg.norm(w)
    # the basis: orthonormal products C = P (c U) of the same combinations of the directions
    basis = got.basis(fft, new.size, 1e-8)
    assert basis.size == 5
    C = basis.C.astype(np.float64)
    assert np.abs(C @ C.T - np.eye(5)).max() <= 1e-6
    AU = (K[np.ix_(new, new)] @ basis.U.T).T
    AU -= AU.mean(axis=1, keepdims=True)
    assert np.abs(AU - C).max() <= 1e-5 * np.abs(C).max()


def test_basis_leaves_out_dependent_directions():
    """A repeated direction (and a much longer multiple of one: the directions' lengths span decades in
    a solve) is left out, not amplified; the rest keep their span."""
    fft, op, h, K = _grid_case()
    idx = np.flatnonzero(h.ravel() > np.quantile(h, 0.6))
    rng = np.random.default_rng(3)
    U = rng.standard_normal((3, idx.size))
    U = np.concatenate([U, U[:1], 1e6 * U[1:2]])
    U -= U.mean(axis=1, keepdims=True)
    W = (K[np.ix_(idx, idx)] @ U.T).T.astype(np.float32)
    basis = CarriedSpace(idx, U, W).basis(fft, idx.size, 1e-8)
    assert basis.size == 3
    # U lies in the span of the basis's directions
    coef, *_ = np.linalg.lstsq(basis.U.T, U[:3].T, rcond=None)
    assert np.linalg.norm(basis.U.T @ coef - U[:3].T) <= 1e-5 * np.linalg.norm(U[:3])


def test_directions_kept_after_a_solve():
    """after_solve: the solve's own directions first (their raw products, the means P took off added
    back), then the carried ones, ``count`` in all."""
    A, B, b = _system(200, 11)
    gm = SingleGMRES(b.size, 100, _allsum, flexible=True, work=np.float32)
    means = []

    def A_mean(z, out):                 # an operator whose product loses a known mean, as P's
        full = A @ z.astype(np.float64)
        means.append(full.mean())
        np.copyto(out, full - full.mean(), casting="same_kind")
    gm.solve(A_mean, _ops(A, B)[1], b, np.empty(b.size), 1e-4, 0.0, 300)
    k = gm.arnoldi[0]
    older = CarriedSpace(np.arange(b.size), np.ones((4, b.size)), np.full((4, b.size), 2.0, np.float32))
    space = CarriedSpace.after_solve(gm, means, np.arange(b.size), k + 2, older=older)
    assert space.size == k + 2 and np.array_equal(space.U[:k], gm.Z[:k]) and np.all(space.U[k:] == 1.0)
    for u, w in zip(space.U[:k], space.W[:k]):
        ref = A @ u.astype(np.float64)
        assert np.linalg.norm(w - ref) <= 1e-5 * np.linalg.norm(ref)
    assert np.all(space.W[k:] == 2.0)
    assert CarriedSpace.after_solve(gm, means, np.arange(b.size), 3).size == 3
    # memory: a copy in the work dtype, its float32 product, and the basis's pair of each while a step runs
    assert CarriedSpace.count(1000, 4, 30, 16000 * 12) == 12
    assert CarriedSpace.count(1000, 8, 30, 1e12) == 30
    assert CarriedSpace.count(1000, 4, 30, 15999) == 0


def test_carried_directions_serve_then_start_from_the_residual():
    rng = np.random.default_rng(5)
    U, AU = rng.standard_normal((3, 50)), rng.standard_normal((3, 50)).astype(np.float32)
    start = rng.standard_normal(50)
    carried = CarriedDirections(U, AU, start)
    y, x = np.zeros(50), rng.standard_normal(50)
    assert not carried.serve_product(y)                   # no direction pending: the operator's own
    for j in range(3):
        assert carried.next_input(x) is x                 # not yet: the directions come first
        assert carried.serve_direction(y) and np.array_equal(y, U[j])
        assert carried.serve_product(y) and np.array_equal(y, AU[j])
        assert not carried.serve_product(y)
    assert not carried.serve_direction(y) and carried.served == 3
    assert carried.next_input(x) is start and carried.next_input(x) is x


def test_exact_step_starts_from_the_residual_orthogonal_to_the_products():
    fft, op, h, K = _grid_case()
    idx = np.flatnonzero(h.ravel() > np.quantile(h, 0.6))
    rng = np.random.default_rng(6)
    U = rng.standard_normal((4, idx.size))
    U -= U.mean(axis=1, keepdims=True)
    space = CarriedSpace(idx, U, (K[np.ix_(idx, idx)] @ U.T).T.astype(np.float32))
    b = rng.standard_normal(idx.size)
    carried = CarriedDirections.of_space(space, fft, idx.size, 1e-8, b)
    C = carried.AU.astype(np.float64)
    assert np.abs(C @ carried.start).max() <= 1e-6 * np.linalg.norm(b)
    assert np.linalg.norm(carried.start - (b - C.T @ (C @ b))) <= 1e-6 * np.linalg.norm(b)


def test_changing_steps_carry_across_the_set_changes():
    """A/A0 ~ 7.6 % at 10 m/s, contact-set steps: with the map (default) against without (0), both
    carrying into the exact step.  The answer to the solver's tolerance, fewer iterations and pairs
    (the map's own pairs, one per grid for the kernel and one per map, included)."""
    on, act_on = paper_contact_solve(CARRY_OPEN)
    off, act_off = paper_contact_solve(dict(CARRY_OPEN, vc_carry_map_cost="0"))
    assert on.converged and off.converged and max(on.residual, off.residual) <= 1e-8
    assert on.diagnostics["step_modes"][-1][1] == "contact"
    assert on.diagnostics["carried_directions"] > off.diagnostics["carried_directions"] > 0
    differ = int(np.count_nonzero(act_on != act_off))     # points on the contact line may fall either way
    assert differ <= 4, differ
    assert abs(on.mu / off.mu - 1) <= 1e-6, (on.mu, off.mu)
    assert on.linear_iterations < 0.9 * off.linear_iterations and on.fft_pairs < 0.95 * off.fft_pairs


def test_no_map_where_the_kernel_exceeds_carry_memory():
    """The map's kernel (4 N^2 bytes on every rank, 0.26 MB at 256^2) must fit within half of
    carry_memory: with less, the fine grid's steps are those without the map (the coarse grids' kernels
    still fit)."""
    small = dict(CARRY_OPEN, vc_carry_memory="5e5")
    capped, _ = paper_contact_solve(small)
    off, _ = paper_contact_solve(dict(small, vc_carry_map_cost="0"))
    mapped, _ = paper_contact_solve(dict(CARRY_OPEN, vc_carry_memory="6e5"))
    assert capped.diagnostics["linear_history"] == off.diagnostics["linear_history"]
    assert mapped.diagnostics["linear_history"] != off.diagnostics["linear_history"]


@pytest.mark.parametrize("options", [CARRY_OPEN, dict(CARRY_OPEN, vc_carry_map_cost="0")], ids=["map", "no map"])
def test_directions_kept_only_to_be_used(options, monkeypatch):
    """A step keeps its directions (after_solve: copies and products over K vectors of the set) only
    for a next step that uses them: on the same set, or mapped to a changed one.  Each kept set goes
    into exactly one basis; without the map only the exact steps' are kept."""
    kept, used = [], []
    after_solve, basis = CarriedSpace.after_solve.__func__, CarriedSpace.basis

    def keep(cls, *args, **kw):
        kept.append(1)
        return after_solve(cls, *args, **kw)

    def use(self, *args, **kw):
        used.append(1)
        return basis(self, *args, **kw)
    monkeypatch.setattr(CarriedSpace, "after_solve", classmethod(keep))
    monkeypatch.setattr(CarriedSpace, "basis", use)
    r, _ = paper_contact_solve(options)
    assert r.converged and r.diagnostics["carried_directions"] > 0
    assert len(kept) == len(used) > 0
    changes = r.diagnostics["active_set_changes"]
    if options.get("vc_carry_map_cost") == "0":         # the exact steps (no change) of the levels that carry
        assert len(kept) <= changes.count(0)
