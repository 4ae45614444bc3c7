"""The smoothing after a prolongation (vecontact/solver/warmstart.smooth_gap): Chebyshev step sizes,
checked against the Chebyshev polynomial's bound and, away from contact, against the closed form of
the linear sweeps mode by mode (stiffness from tests/reference/dense.py, numpy FFTs); and the coarse
grids' SlabFFT cache (warmstart.coarse_fft)."""
import math

import numpy as np
import pytest
from mpi4py import MPI

from reference.cases import L_PAPER, NU, small_spectrum
from reference.dense import multiplier, random_surface

from vecontact.core.pfft import SlabFFT
from vecontact.physics.modulus import HavriliakNegami
from vecontact.solver.operator import ContactOperator
from vecontact.solver.warmstart import chebyshev_nodes, coarse_fft, smooth_gap

N = 24


def _operator(v, seed):
    """The ContactOperator of a 24^2 paper-like surface under HN at ``v`` (m/s), 1e5 Pa, one rank."""
    h = random_surface(N, L_PAPER, small_spectrum(N), seed=seed)
    fft = SlabFFT(MPI.COMM_SELF, N, planner="estimate", wisdom_file=False)
    return ContactOperator(fft, L_PAPER, HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10, NU), v, 1e5, h)


@pytest.mark.parametrize("n, ratio", [(1, 6.0), (4, 4.0), (6, 6.0), (9, 20.0)])
def test_chebyshev_steps_damp_the_interval_by_the_chebyshev_bound(n, ratio):
    # max over [lo, hi] of |prod_k (1 - x / lambda_k)| = 1 / T_n((hi + lo) / (hi - lo)), reached at the
    # interval's ends (Chebyshev extrema), so sampling that includes them finds it to rounding
    lo, hi = 1.0 / ratio, 1.0
    lam = chebyshev_nodes(lo, hi, n)
    assert lam.shape == (n,) and np.all(np.diff(lam) < 0) and lo < lam.min() and lam.max() < hi
    x = np.linspace(lo, hi, 20001)
    damping = np.abs(np.prod(1.0 - x[:, None] / lam[None, :], axis=1)).max()
    bound = 1.0 / math.cosh(n * math.acosh((hi + lo) / (hi - lo)))
    assert damping == pytest.approx(bound, rel=1e-9)
    # below the interval nothing grows (the polynomial is 1 at 0 and monotone down to lo)
    low = np.linspace(0.0, lo, 1001)
    assert np.all(np.abs(np.prod(1.0 - low[:, None] / lam[None, :], axis=1)) <= 1.0 + 1e-12)


@pytest.mark.parametrize("v", [1e-3, 1.0])
def test_sweeps_away_from_contact_follow_the_closed_form(v):
    # gap everywhere far above 0: no projection acts, and the sweeps g <- g - (1 + p_h + m g) / lambda_k
    # multiply each Fourier mode q != 0 of g + D / m by prod_k (1 - m_q / lambda_k) (D the transform
    # of 1 + p_h) and move the mean by -D_0 sum_k 1 / lambda_k
    op = _operator(v, seed=3)
    m = multiplier(N, L_PAPER, op.modulus, NU, v) * (op.ell / op.sigma0)      # sigma0 per h_rms, independent
    mmax = np.abs(m).max()
    assert op.stiffness_bounds()[1] == pytest.approx(mmax, rel=1e-12)
    rng = np.random.default_rng(7)
    g0 = 1e3 + rng.standard_normal((N, N))
    sweeps, ratio = 6, 6.0
    g = smooth_gap(op, g0, sweeps, ratio)
    lam = chebyshev_nodes(mmax / ratio, mmax, sweeps)
    D = np.fft.fftn(1.0 + op.p_h)
    G0 = np.fft.fftn(g0)
    nz = m != 0
    G = np.empty_like(G0)
    G[nz] = np.prod(1.0 - m[nz, None] / lam, axis=-1) * (G0[nz] + D[nz] / m[nz]) - D[nz] / m[nz]
    G[~nz] = G0[~nz] - D[~nz] * np.sum(1.0 / lam)
    expected = np.fft.ifftn(G).real
    assert g.min() > 0.0                              # the projection never acted
    assert np.abs(g - expected).max() <= 1e-9 * np.abs(g0).max()
    # the sweeps changed the field by far more than that tolerance
    assert np.abs(g - g0).max() > 1e-3


def test_sweeps_keep_the_gap_nonnegative_and_do_nothing_when_asked_for_none():
    op = _operator(0.01, seed=5)
    g0 = np.maximum(op.hhat.max() - op.hhat, 0.0)      # a rigid flat touching the highest point
    g = smooth_gap(op, g0, 6, 6.0)
    assert g.min() == 0.0 and np.count_nonzero(g == 0.0) >= 1
    assert smooth_gap(op, g0, 0, 6.0) is g0


def test_sweeps_in_given_arrays_are_the_same_numbers():
    """``out`` (also the input itself): the same bits as the sweeps in their own array
    (the same operations in the same order), and the input untouched unless it is ``out``."""
    op = _operator(1.0, seed=4)
    g0 = np.maximum(np.quantile(op.hhat, 0.7) - op.hhat, 0.0)
    ref = smooth_gap(op, g0, 4, 6.0)
    keep = g0.copy()
    out = np.empty_like(g0)
    assert smooth_gap(op, g0, 4, 6.0, out=out) is out
    assert np.array_equal(out, ref) and np.array_equal(g0, keep)
    inplace = g0.copy()
    assert smooth_gap(op, inplace, 4, 6.0, out=inplace) is inplace
    assert np.array_equal(inplace, ref)
    assert not np.array_equal(ref, g0)


def test_a_cycle_of_smoothed_steps_is_broken():
    """The sharp rubber (HN alpha = beta = 0.8) at 1 mm/s on the tests' 128^2 surface, 59 % in contact:
    the smoothing after each changing free-set step (step_sweeps) sent the iterate back to where it
    was two steps before, three points flipping to and fro, and the solve ran its 100 Newton
    iterations at a measure of 3.7 (measured). Once the measure comes back, the steps go unsmoothed
    and the solve converges to the contact set of a solve never smoothed (one grid point)."""
    from vecontact.solver import solve_contact
    n = 128
    h = random_surface(n, L_PAPER, small_spectrum(n), seed=4)
    mod = HavriliakNegami(3e6, 3e9, 0.8, 0.8, 1e-6, NU)
    fft = SlabFFT(MPI.COMM_SELF, n, planner="estimate", wisdom_file=False)
    r, plain = (solve_contact(fft, L_PAPER, h, mod, 0.001, 1e5, tolerance=1e-8, store=(), petsc_options=opts)
                for opts in (None, ["-vc_step_sweeps 0"]))
    assert r.converged and plain.converged and r.iterations < 30
    assert abs(r.area - plain.area) * n * n <= 1 and 0.55 < r.area < 0.65
    stuck = solve_contact(fft, L_PAPER, h, mod, 0.001, 1e5, tolerance=1e-8, store=(), max_iterations=30,
                          petsc_options=["-vc_step_return_rtol 0", "-vc_fallback none"])
    assert not stuck.converged and stuck.residual > 1.0


def test_coarse_grids_follow_the_fine_grids_wisdom_file(tmp_path):
    # the coarse SlabFFTs are cached per process; a fine grid with another wisdom file must get coarse
    # grids of its own, made with that file (not the first fine grid's)
    files = [str(tmp_path / "a.pkl"), str(tmp_path / "b.pkl")]
    coarse = []
    for path in files:
        fine = SlabFFT(MPI.COMM_SELF, 16, planner="estimate", wisdom_file=path)
        coarse.append(coarse_fft(fine, 8))
        assert coarse[-1].wisdom_file == path and coarse[-1].N == 8
        assert coarse_fft(fine, 8) is coarse[-1]          # cached for that file
    assert coarse[0] is not coarse[1]
    no_file = SlabFFT(MPI.COMM_SELF, 16, planner="estimate", wisdom_file=False)
    assert coarse_fft(no_file, 8).wisdom_file is None
