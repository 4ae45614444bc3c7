"""Collective surface tests: mpiexec -n 2 python -m pytest tests/mpi"""
import os
import sys

import numpy as np
from mpi4py import MPI

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scripts"))
import surface_check  # noqa: E402

from vecontact.core import surface  # noqa: E402
from vecontact.core.pfft import SlabFFT  # noqa: E402
from vecontact.errors import InputError  # noqa: E402


def test_generate_bit_identical_to_single_rank(comm):
    for N in (45, 48):
        fft = SlabFFT(comm, N, planner="estimate", wisdom_file=False)
        h = fft.gather(surface.generate(fft, surface_check.L, surface_check.psd_powerlaw, 77))
        single = SlabFFT(MPI.COMM_SELF, N, planner="estimate", wisdom_file=False)
        ref = surface.generate(single, surface_check.L, surface_check.psd_powerlaw, 77)
        if comm.rank == 0:
            assert np.array_equal(h, ref)
        st = surface.statistics(fft, fft.scatter(ref if comm.rank == 0 else None), surface_check.L)
        assert comm.bcast(st, root=0) == st
        assert st == surface.statistics(single, ref, surface_check.L) or np.allclose(
            list(st.values()), list(surface.statistics(single, ref, surface_check.L).values()), rtol=1e-13)


def test_load_npy_h5_and_errors(comm, tmp_path_factory):
    d = comm.bcast(str(tmp_path_factory.mktemp("surf")) if comm.rank == 0 else None, root=0)
    N = 20
    ref = np.arange(N * N, dtype=float).reshape(N, N) * 1e-9
    if comm.rank == 0:
        import h5py

        np.save(os.path.join(d, "s.npy"), ref)
        with h5py.File(os.path.join(d, "s.h5"), "w") as f:
            f["z"] = ref
        np.save(os.path.join(d, "bad.npy"), ref[:-1])
    comm.Barrier()
    fft = SlabFFT(comm, N, planner="estimate", wisdom_file=False)
    for name in ("s.npy", "s.h5"):
        h = surface.load(fft, os.path.join(d, name))
        assert np.array_equal(h, ref[fft.row_start:fft.row_stop])
    for name in ("bad.npy", "nothere.h5"):
        try:
            surface.load(fft, os.path.join(d, name))
            raised = False
        except InputError as e:
            raised = e.key == "surface.file"
        assert all(comm.allgather(raised))
