"""Surface generation / loading on whatever number of ranks this runs on.

usage: mpiexec -n P python surface_check.py OUTDIR
Writes OUTDIR/surf_<P>.npz (gathered surfaces, keys "<N>_<amplitudes>") and checks the files written
by tests/test_surface.py into OUTDIR (good ones load to the original rows, bad ones raise InputError on
every rank).  Prints SURFACE_OK <P>; MPI Abort on failure.
"""
import glob
import os
import sys

import numpy as np
from mpi4py import MPI

from vecontact.core import surface
from vecontact.core.pfft import SlabFFT
from vecontact.errors import InputError

GEN_SIZES = (48, 45, 64)
SEED = 20150302
L = 2 * np.pi / 2.5e5


def psd_powerlaw(q, q0=2.5e5, C0=1.0616e-28, H=0.8):
    """Self-affine C0 (q/q0)^-2(1+H) above q0, no upper cut-off (so the Nyquist modes are exercised)."""
    q = np.asarray(q, dtype=float)
    return np.where(q >= q0 * (1 - 1e-12), C0 * (np.maximum(q, q0) / q0) ** (-2 * (1 + H)), 0.0)


def generate_all(comm):
    out = {}
    for N in GEN_SIZES:
        fft = SlabFFT(comm, N, planner="measure", wisdom_file=False)
        for amp in ("fixed", "gaussian"):
            h = surface.generate(fft, L, psd_powerlaw, SEED, amplitudes=amp)
            g = fft.gather(h)
            if comm.rank == 0:
                out[f"{N}_{amp}"] = g
    return out


def check_files(comm, outdir):
    good = sorted(glob.glob(os.path.join(outdir, "good_*")))
    bad = sorted(glob.glob(os.path.join(outdir, "bad_*")))
    ref = np.load(os.path.join(outdir, "reference.npy"))
    N = ref.shape[0]
    fft = SlabFFT(comm, N, planner="estimate", wisdom_file=False)
    for path in good:
        ds = "heights" if path.endswith("named.h5") else None
        h = surface.load(fft, path, dataset=ds)
        assert h.shape == fft.local_real_shape and h.dtype == np.float64
        assert np.array_equal(h, ref[fft.row_start:fft.row_stop]), path
    for path in bad:
        ds = "nothere" if "missingds" in path else None
        try:
            surface.load(fft, path, dataset=ds)
        except InputError as e:
            assert e.key == "surface.file", e.key
            msgs = comm.allgather(str(e))
            assert all(m == msgs[0] for m in msgs)
        else:
            raise AssertionError(f"{path} loaded without error")
    return len(good), len(bad)


if __name__ == "__main__":
    comm = MPI.COMM_WORLD
    outdir = sys.argv[1]
    try:
        res = generate_all(comm)
        if comm.rank == 0:
            np.savez(os.path.join(outdir, f"surf_{comm.size}.npz"), **res)
        ng, nb = (0, 0)
        if os.path.exists(os.path.join(outdir, "reference.npy")):
            ng, nb = check_files(comm, outdir)
    except BaseException:
        import traceback

        traceback.print_exc()
        sys.stderr.flush()
        comm.Abort(1)
    if comm.rank == 0:
        print("SURFACE_OK", comm.size, ng, nb)
