"""The directions an exact contact-set step carries over from the step before it (carry.py).

* the Arnoldi relation a flexible SingleGMRES leaves behind (``arnoldi``): A Z[j] = sum_i G[i, j] V[i]
  to float32 rounding, with restarts and with rows rescaled by powers of two;
* CarriedDirections: its products are A times its directions, it serves them in FGMRES's order
  (a direction, then that direction's product), and its count respects the memory;
* the solver on a paper surface at 10 m/s, default against ``-vc_carry_directions 0``: the same Newton
  path and answer, the exact step started from the carried directions and took fewer Krylov
  iterations and FFT pairs.
"""
import numpy as np
import pytest
from mpi4py import MPI

from reference.cases import L_PAPER, NU, Q0
from reference.krylov import allsum as _allsum, operators as _ops, system as _system

from vecontact.core.pfft import SlabFFT
from vecontact.core.surface import generate
from vecontact.physics.modulus import HavriliakNegami
from vecontact.physics.spectrum import SelfAffine
from vecontact.solver import solve_contact
from vecontact.solver.carry import CarriedDirections
from vecontact.solver.single import SingleGMRES


def _flexible_solve(A, B, b, restart, rtol, work=np.float64):
    gm = SingleGMRES(b.size, restart, _allsum, flexible=True, work=work)
    x = np.empty(b.size)
    its, _ = gm.solve(*_ops(A, B), b, x, rtol, 0.0, 500)
    return gm, its, x


@pytest.mark.parametrize("restart, scale", [(100, 1.0), (7, 1.0), (100, 2.0 ** 40)])
def test_arnoldi_relation(restart, scale):
    """scale 2^40: the rows' lengths leave 2^+-32, so rows are rescaled (single._RANGE), which G must
    follow; restart 7: the relation is the last cycle's."""
    A, B, b = _system(200, 7, scale)
    gm, its, _ = _flexible_solve(A, B, b, restart, 1e-5)
    k, G = gm.arnoldi
    assert k == (its - 1) % restart + 1 and G.shape == (k + 1, k)
    if scale > 1:
        assert gm.rescales > 0
    AZ = gm.Z[:k].astype(np.float64) @ A.T               # rows A Z[j]
    VG = G.T @ gm.V[:k + 1].astype(np.float64)           # rows sum_i G[i, j] V[i]
    for j in range(k):
        # the basis is float32: the relation holds to its rounding (~6e-8 of the product's size)
        assert np.linalg.norm(AZ[j] - VG[j]) <= 1e-5 * np.linalg.norm(AZ[j]), j
    # without a preconditioner's memory (GMRES, not FGMRES) nothing is recorded
    plain = SingleGMRES(b.size, restart, _allsum, flexible=False)
    plain.solve(*_ops(A, B), b, np.empty(b.size), 1e-3, 0.0, 50)
    assert plain.arnoldi is None


def test_carried_directions_products_order_and_count():
    A, B, b = _system(200, 11)
    gm, its, _ = _flexible_solve(A, B, b, 100, 1e-4, work=np.float32)
    k = gm.arnoldi[0]
    carried = CarriedDirections(gm, 5)
    assert carried.size == 5 and carried.U.dtype == np.float32 and carried.AU.dtype == np.float32
    assert np.array_equal(carried.U, gm.Z[k - 5:k])      # the last cycle's last directions
    for u, au in zip(carried.U, carried.AU):
        ref = A @ u.astype(np.float64)
        assert np.linalg.norm(au - ref) <= 1e-5 * np.linalg.norm(ref)
    y = np.zeros(b.size)
    assert not carried.serve_product(y)                   # no direction pending: the operator's own
    for j in range(5):
        assert carried.serve_direction(y) and np.array_equal(y, carried.U[j])
        assert carried.serve_product(y) and np.array_equal(y, carried.AU[j])
        assert not carried.serve_product(y)
    assert not carried.serve_direction(y) and carried.served == 5
    assert CarriedDirections(gm, 10 * k).size == k       # never more than the cycle has
    # memory: 8 bytes an entry with a float32 copy and its float32 product
    assert CarriedDirections.count(1000, 4, 30, 8000 * 12) == 12
    assert CarriedDirections.count(1000, 8, 30, 1e12) == 30
    assert CarriedDirections.count(1000, 4, 30, 7999) == 0


def _solve(options):
    N = 256
    fft = SlabFFT(MPI.COMM_SELF, N, planner="estimate", wisdom_file=False)
    h = generate(fft, L_PAPER, SelfAffine(Q0, 4 * Q0, N // 16 * Q0, 0.8, 1.0616e-28), 1)
    hn = HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10, NU)
    r = solve_contact(fft, L_PAPER, h, hn, 10.0, 1.0e5, tolerance=1e-8, store=("pressure",),
                      petsc_options=options)
    return r, fft.gather(r.pressure > 0)


def test_exact_step_carries_the_last_steps_directions():
    """A/A0 ~ 7 % at 10 m/s: contact-set steps, whose exact step follows a float32 FGMRES step on the
    same set and must cut its residual by less than mixed_reduction_max (the float32 products)."""
    on, act_on = _solve({})
    off, act_off = _solve({"vc_carry_directions": "0"})
    d_on, d_off = on.diagnostics, off.diagnostics
    assert on.converged and off.converged and max(on.residual, off.residual) <= 1e-8
    assert d_on["step_modes"][-1][1] == "contact"
    assert d_on["carried_directions"] > 0 and d_off["carried_directions"] == 0
    # the same Newton path up to the exact step, which only starts from more
    assert d_on["active_set_changes"] == d_off["active_set_changes"]
    assert d_on["linear_history"][:-1] == d_off["linear_history"][:-1]
    differ = int(np.count_nonzero(act_on != act_off))     # points on the contact line may fall either way
    assert differ <= 4, differ
    assert abs(on.mu / off.mu - 1) <= 1e-6, (on.mu, off.mu)
    # the carried directions cost no FFT pair and are not counted as iterations
    assert on.linear_iterations < off.linear_iterations and on.fft_pairs < off.fft_pairs
