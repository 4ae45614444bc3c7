"""SlabFFT (vecontact.core.pfft): numpy agreement on 1 rank in-process and on 2, 3, 4 ranks under
mpiexec (tests/scripts/pfft_check.py), wisdom handling, allocation-free hot path."""
import os
import pickle
import sys
import tracemalloc

import numpy as np
import pytest
from mpi4py import MPI

from mpi_util import run_mpi
from vecontact.core.pfft import SlabFFT, apply_seconds, column_split, split_range

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "scripts"))
import pfft_check  # noqa: E402


@pytest.mark.parametrize("N", pfft_check.SIZES)
def test_matches_numpy_one_rank(N):
    pfft_check.check_one(MPI.COMM_WORLD if MPI.COMM_WORLD.size == 1 else MPI.COMM_SELF, N)


@pytest.mark.parametrize("N", pfft_check.SIZES)
def test_single_precision_one_rank(N):
    pfft_check.check_single(MPI.COMM_WORLD if MPI.COMM_WORLD.size == 1 else MPI.COMM_SELF, N)


@pytest.mark.parametrize("N", pfft_check.SIZES)
def test_scale_and_release_arrays_one_rank(N):
    pfft_check.check_scale_and_release(MPI.COMM_WORLD if MPI.COMM_WORLD.size == 1 else MPI.COMM_SELF, N)


@pytest.mark.parametrize("N", pfft_check.SIZES)
def test_apply_across_precisions_one_rank(N):
    pfft_check.check_across(MPI.COMM_WORLD if MPI.COMM_WORLD.size == 1 else MPI.COMM_SELF, N)


@pytest.mark.parametrize("nprocs", [2, 3, 4])
def test_matches_numpy_mpi(nprocs):
    # 4 ranks oversubscribe the 2 cores: N <= 64 only
    proc = run_mpi(nprocs, [os.path.join(HERE, "scripts", "pfft_check.py")], timeout=240)
    assert f"PFFT_OK {nprocs}" in proc.stdout


def test_splits():
    for n, size in [(9, 4), (64, 3), (1025, 2), (2049, 2), (2049, 4), (30, 7)]:
        rows = [split_range(n, size, r) for r in range(size)]
        cols = column_split(n, size)
        for parts in (rows, cols):
            assert parts[0][0] == 0 and parts[-1][1] == n
            assert all(b > a for a, b in parts)
            assert all(parts[i][1] == parts[i + 1][0] for i in range(size - 1))
    # no power-of-two-strided Fourier slabs at the production sizes
    for nc in (1025, 2049):
        assert all((b - a) % 32 for a, b in column_split(nc, 2))


def test_bad_arguments():
    with pytest.raises(ValueError):
        SlabFFT(MPI.COMM_SELF, 1, wisdom_file=False)
    with pytest.raises(ValueError):
        SlabFFT(MPI.COMM_SELF, 8, planner="fast", wisdom_file=False)
    with pytest.raises(ValueError, match="precision"):
        SlabFFT(MPI.COMM_SELF, 8, precision="half", wisdom_file=False)
    fft = SlabFFT(MPI.COMM_SELF, 8, planner="estimate", wisdom_file=False)
    with pytest.raises(ValueError):
        fft.forward(np.zeros((8, 9)))
    with pytest.raises(ValueError):
        fft.backward(np.zeros((8, 4), complex))


def test_no_allocation_in_hot_path():
    N = 64
    fft = SlabFFT(MPI.COMM_SELF, N, planner="estimate", wisdom_file=False)
    x = fft.real_array()
    x[...] = np.random.default_rng(0).standard_normal(x.shape)
    F, y = fft.fourier_array(), fft.real_array()
    m = fft.fourier_array() + 1.0
    fft.forward(x, F), fft.backward(F, y), fft.apply(x, m, y)  # warm up
    tracemalloc.start()
    for _ in range(20):
        fft.forward(x, F)
        fft.backward(F, y)
        fft.apply(x, m, y)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    assert peak < 8 * N * N / 4, peak  # far below one N x N array: only small Python objects


def test_apply_seconds_counts_apply_only():
    """apply_seconds(): the wall time inside apply, over all instances; forward/backward are not in it."""
    import time
    a = SlabFFT(MPI.COMM_SELF, 64, planner="estimate", wisdom_file=False)
    b = SlabFFT(MPI.COMM_SELF, 32, planner="estimate", wisdom_file=False)
    xa, xb = a.real_array(), b.real_array()
    s0 = apply_seconds()
    t0 = time.perf_counter()
    for _ in range(5):
        a.apply(xa, 2.0, xa)
        b.apply(xb, 2.0, xb)
    wall = time.perf_counter() - t0
    s1 = apply_seconds()
    assert 0.0 < s1 - s0 <= wall
    a.forward(xa), a.backward(a.fourier_array())
    assert apply_seconds() == s1


def test_time_pair_is_a_pair_that_counts_nowhere():
    """time_pair: (fastest, median) of the timed pairs, the fastest no more than the median nor than the
    wall time of all of them; neither the counters nor apply_seconds move; bad repeats refused."""
    import time
    fft = SlabFFT(MPI.COMM_SELF, 64, planner="estimate", wisdom_file=False)
    x = fft.real_array()
    fft.apply(x, 2.0, x)
    fft.forward(x)
    before, s0 = (fft.pairs, fft.transforms), apply_seconds()
    t0 = time.perf_counter()
    fastest, middle = fft.time_pair(5)
    wall = time.perf_counter() - t0
    assert 0.0 < fastest <= middle and 5 * fastest <= wall
    assert (fft.pairs, fft.transforms) == before and apply_seconds() == s0
    with pytest.raises(ValueError, match="repeats"):
        fft.time_pair(0)


def test_wisdom_file(tmp_path):
    path = tmp_path / "sub" / "wisdom.pkl"
    SlabFFT(MPI.COMM_SELF, 24, planner="measure", wisdom_file=str(path))
    assert path.exists()
    wis = pickle.loads(path.read_bytes())
    assert len(wis) == 3 and len(wis[0]) > 0
    # reload (and corrupt files / unwritable places never fail)
    SlabFFT(MPI.COMM_SELF, 24, planner="measure", wisdom_file=str(path))
    path.write_bytes(b"garbage")
    SlabFFT(MPI.COMM_SELF, 24, planner="estimate", wisdom_file=str(path))
    SlabFFT(MPI.COMM_SELF, 24, planner="estimate", wisdom_file="/proc/nonexistent/dir/w.pkl")


def test_radial_psd_single_mode():
    N, L = 32, 1e-5
    fft = SlabFFT(MPI.COMM_SELF, N, planner="estimate", wisdom_file=False)
    i = np.arange(N)
    A = 2e-9
    h = fft.real_array()
    h[...] = A * np.cos(2 * np.pi * 5 * i / N)[:, None] * np.ones(N)[None, :]
    q, C = fft.radial_psd(h, L)
    dq = 2 * np.pi / L
    # modes (+-5, 0), |h_q| = A/2 each, in the k=5 annulus
    k5 = np.argmin(np.abs(q / dq - 5))
    kk = np.hypot(*np.meshgrid(np.fft.fftfreq(N, 1 / N), np.fft.fftfreq(N, 1 / N)))
    nmodes = np.sum((kk >= 4.5) & (kk < 5.5))
    assert C[k5] == pytest.approx(2 * (A / 2) ** 2 / dq ** 2 / nmodes, rel=1e-12)
    assert np.sum(C > 1e-20 * C.max()) == 1
