"""Collective SlabFFT tests: mpiexec -n 2 python -m pytest tests/mpi"""
import os
import sys

import numpy as np
import pytest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scripts"))
import pfft_check  # noqa: E402

from vecontact.core.pfft import SlabFFT  # noqa: E402


@pytest.mark.parametrize("N", pfft_check.SIZES)
def test_matches_numpy(comm, N):
    if comm.size > N // 2:
        pytest.skip("too many ranks for this N")
    pfft_check.check_one(comm, N)
    pfft_check.check_single(comm, N)


def test_radial_psd_identical_on_ranks(comm):
    N, L = 40, 2e-5
    fft = SlabFFT(comm, N, planner="estimate", wisdom_file=False)
    full = np.random.default_rng(9).standard_normal((N, N))
    h = fft.scatter(full if comm.rank == 0 else None)
    q, C = fft.radial_psd(h, L)
    q2, C2 = comm.bcast((q, C), root=0)
    assert np.array_equal(q, q2) and np.array_equal(C, C2)
    assert fft.pairs == 0


def test_time_pair_same_figures_on_every_rank(comm):
    """time_pair is collective and every rank returns rank 0's figures (the farm stores one of them)."""
    fft = SlabFFT(comm, 32, planner="estimate", wisdom_file=False)
    got = fft.time_pair(3)
    assert comm.allgather(got) == [got] * comm.size and 0.0 < got[0] <= got[1]
    assert fft.pairs == 0
