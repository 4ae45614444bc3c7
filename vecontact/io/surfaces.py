"""Surfaces on disk: the ``vecontact surface`` command and distributed row I/O.

Heights are in metres, N x N, axis 0 = x (sliding direction). Rank 0 writes; the other ranks
send their rows one rank at a time, so no rank ever holds more than its own rows plus one
other rank's rows.
"""
import os

import h5py
import numpy as np

from vecontact.errors import InputError
from vecontact.io.results import atomic_h5


def file_grid_size(path, dataset=None):
    """N of an N x N height file (.npy or .h5: read from its header only; an instrument scan: N of
    the periodic surface made from it, see :mod:`vecontact.io.topography`)."""
    from vecontact.io.topography import is_instrument_file, read_topography
    if is_instrument_file(path):
        return int(read_topography(path, dataset)[0].shape[0])
    try:
        if path.endswith(".npy"):
            shape = np.load(path, mmap_mode="r").shape
        else:
            with h5py.File(path, "r") as f:
                name = dataset or _only_2d(f, path)
                if name not in f:
                    raise InputError("surface.dataset", f"no dataset {name!r} in {path}")
                shape = f[name].shape
    except InputError:
        raise
    except Exception as exc:
        raise InputError("surface.file", f"cannot read {path} ({type(exc).__name__})") from None
    if len(shape) != 2 or shape[0] != shape[1] or shape[0] < 4:
        raise InputError("surface.file", f"heights must be an N x N array with N >= 4, got shape {shape}")
    return int(shape[0])


def _only_2d(f, path):
    names = [k for k, v in f.items() if isinstance(v, h5py.Dataset) and v.ndim == 2]
    if len(names) != 1:
        raise InputError("surface.dataset", f"{path} holds {len(names)} 2-D datasets; name one")
    return names[0]


def write_rows(comm, dset, row_start, local):
    """Write each rank's rows [row_start, row_start + len(local)) into ``dset`` (rank 0 only)."""
    if comm.rank == 0:
        dset[row_start:row_start + local.shape[0]] = local
        for src in range(1, comm.size):
            start, rows = comm.recv(source=src, tag=11)
            dset[start:start + rows.shape[0]] = rows
    else:
        comm.send((row_start, np.ascontiguousarray(local)), dest=0, tag=11)


def write_job_surfaces(job, path, comm):
    """Generate every (q1, seed) surface of a job and write them to ``path`` (atomically)."""
    from vecontact.core.pfft import SlabFFT
    from vecontact.runner import spectra
    from vecontact.core.surface import generate, statistics
    from vecontact.job import to_yaml
    from vecontact import __version__

    s = job.surface
    if s.spectrum == "file":
        raise InputError("surface.spectrum", "'vecontact surface' generates surfaces; this job reads one from a file")
    if not path.endswith((".h5", ".hdf5")):
        raise InputError("output", f"surfaces are written to an .h5 file, got {path!r}")
    L = s.length
    psds = spectra(job, comm)
    items = []
    for q1 in s.q1:
        n = s.grid(q1)
        fft = SlabFFT(comm, n)
        psd = psds[float(q1)]
        for seed in s.realisations(q1):
            h = generate(fft, L, psd, seed, amplitudes=s.amplitudes)
            items.append((q1, seed, n, fft, h, statistics(fft, h, L), psd))

    def fill(f):
        f.attrs["vecontact_version"] = __version__
        f.attrs["job_yaml"] = to_yaml(job)
        f.attrs["units"] = "heights: m; L: m; q0, q1: 1/m"
        for q1, seed, n, fft, h, st, psd in items:
            d = f.create_dataset(f"q1_{q1:.6e}_seed_{seed}", shape=(n, n), dtype="f8")
            if s.qr is not None:
                d.attrs["qr"] = s.qr
            d.attrs.update({"L": L, "q0": s.q0, "q1": q1, "seed": seed, "N": n,
                            "hrms": st["hrms"], "slope_rms": st["slope_rms"],
                            "hrms_spectrum": psd.hrms(), "slope_rms_spectrum": np.sqrt(psd.slope2())})
            write_rows(comm, d, fft.row_start, h)

    if comm.rank == 0:
        os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
        atomic_h5(path, fill)
        for q1, seed, n, _, _, st, _ in items:
            print(f"q1 = {q1:.4g} 1/m  seed {seed}  N = {n}  hrms = {st['hrms']:.4e} m  "
                  f"slope_rms = {st['slope_rms']:.4f}")
    else:
        for _, _, _, fft, h, _, _ in items:
            write_rows(comm, None, fft.row_start, h)
