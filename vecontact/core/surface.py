"""Rough surfaces on a distributed grid: generation from a PSD, loading from files, statistics.

Conventions (docs/conventions.md sections 1-2, 6): heights in m on the periodic N x N grid of side L held by
a :class:`vecontact.core.pfft.SlabFFT` (rows ``row_start:row_stop`` on each rank);
h(x) = sum_q h_q exp(i q.x), h_q = fft2(h)/N^2, |h_q|^2 = C(|q|) (2 pi/L)^2 (Persson's PSD C, m^4).

Rank independence: ``generate`` gives the same surface bit for bit on any number of ranks.  Every
Fourier coefficient is a pure function of (seed, signed wavevector index (kx, ky)) through the
counter-based generator :mod:`vecontact.core.rng`, and the inverse transform used here is a
deterministic per-line path (numpy/pocketfft 1-D transforms, one line at a time, whose arithmetic cannot
depend on the batch shape, followed by the bit-exact MPI transpose), not the batched FFTW plans of
SlabFFT whose kernels/plan choice may change the last bits with the decomposition.  Because the keys
are signed wavevectors (not grid positions), surfaces with the same seed at different N share the
phases of their common modes (apart from self-conjugate Nyquist modes).
"""
from __future__ import annotations

import os

import numpy as np
from mpi4py import MPI

from vecontact.core import rng
from vecontact.errors import InputError

_KEY = "surface.file"


# ---------------------------------------------------------------------------------------- generation
def _canonical(fft):
    """Canonical (kx, ky) keys, the 'take conjugate' mask and the 'purely real mode' mask, local shape."""
    N = fft.N
    kx = np.broadcast_to(fft.kx, fft.local_fourier_shape)
    ky = np.broadcast_to(fft.ky, fft.local_fourier_shape)
    selfconj_col = ky == 0
    if N % 2 == 0:
        selfconj_col = selfconj_col | (ky == N // 2)
    kx_self = kx == 0
    if N % 2 == 0:
        kx_self = kx_self | (kx == -(N // 2))
    # in a self-conjugate column, (kx, ky) ~ conj(-kx, ky): the canonical representative has kx > 0
    flip = selfconj_col & (kx < 0) & ~kx_self
    kxc = np.where(flip, -kx, kx)
    real_mode = selfconj_col & kx_self
    return kxc, ky, flip, real_mode


def coefficients(fft, L, psd, seed, amplitudes="fixed"):
    """Local Fourier coefficients h_q (complex, ``fft.local_fourier_shape``, m) of ``generate``.

    ``psd``: vectorised callable C(q) (q in 1/m -> m^4), evaluated only at q > 0 (h_0 = 0).
    ``amplitudes``: "fixed" -> |h_q| = sqrt(C) 2pi/L with uniform random phases (default);
    "gaussian" -> complex Gaussian h_q with <|h_q|^2> = C (2pi/L)^2.
    Self-conjugate modes (ky in {0, N/2}, kx in {0, -N/2}) are real: random sign (fixed) or a real
    Gaussian of variance C (2pi/L)^2.  Hermitian partners within the ky = 0 and ky = N/2 columns are
    derived from the canonical representative, so h_{-q} = conj h_q holds exactly.
    """
    if amplitudes not in ("fixed", "gaussian"):
        raise InputError("surface.amplitudes", f"must be 'fixed' or 'gaussian', got {amplitudes!r}")
    L = float(L)
    if not (L > 0 and np.isfinite(L)):
        raise InputError("surface.L", f"must be a positive length in m, got {L!r}")
    _, _, q = fft.wavevectors(L)
    pos = q > 0
    C = np.zeros(fft.local_fourier_shape)
    if pos.any():
        C[pos] = np.asarray(psd(q[pos]), dtype=np.float64).reshape(-1)
    bad = (~np.isfinite(C)) | (C < 0)
    if fft.comm.allreduce(bool(bad.any()), op=MPI.LOR):
        raise InputError("surface.psd", "the power spectrum C(q) must be finite and >= 0 on the grid")
    amp = np.sqrt(C) * (2.0 * np.pi / L)
    kxc, ky, flip, real_mode = _canonical(fft)
    seed = int(seed)
    if amplitudes == "fixed":
        u = rng.uniform(seed, kxc, ky, stream=0)
        z = np.exp(2j * np.pi * u)
        z[real_mode] = np.where(u[real_mode] < 0.5, 1.0, -1.0)
    else:
        g1, g2 = rng.normal_pair(seed, kxc, ky, stream=0)
        z = (g1 + 1j * g2) * np.sqrt(0.5)
        z[real_mode] = g1[real_mode]
    z[flip] = np.conj(z[flip])
    return amp * z


def synthesize(fft, hq, out=None):
    """Deterministic inverse transform h(x) = sum_q h_q exp(i q.x) (no 1/N^2: h_q are docs/conventions.md
    coefficients).  Bit-identical for any decomposition: one 1-D numpy transform per line (ifft along x
    for each local ky column, MPI transpose, irfft along y for each local row).  Slower than
    ``fft.backward`` (fine for set-up work).  Uses the SlabFFT scratch buffers."""
    fft._check_fourier(hq, "hq")
    if out is None:
        out = fft.real_array()
    B = fft._B
    for j in range(fft.ncols):
        B[:, j] = np.fft.ifft(np.ascontiguousarray(hq[:, j]), norm="forward")
    if fft.size == 1:
        A = B
    else:
        fft._b2a()
        A = fft._A
    N = fft.N
    for i in range(fft.nrows):
        out[i] = np.fft.irfft(A[i], n=N, norm="forward")
    return out


def generate(fft, L, psd, seed, amplitudes="fixed"):
    """Random rough surface, local rows of heights (m), float64 array of ``fft.local_real_shape``.

    L: side of the periodic square (m); psd: C(q) callable (1/m -> m^4); seed: integer.
    The surface has zero mean, |h_q|^2 = C(|q|) (2pi/L)^2 (see ``coefficients``) and is bit-identical
    for any number of ranks (see module docstring).
    """
    return synthesize(fft, coefficients(fft, L, psd, seed, amplitudes))


# ---------------------------------------------------------------------------------------- loading
def _agree(comm, fn):
    """Run ``fn`` on every rank; if it raises InputError on any rank, raise it on all ranks."""
    result, err = None, None
    try:
        result = fn()
    except InputError as e:
        err = (e.key, e.problem)
    errs = comm.allgather(err)
    for e in errs:
        if e is not None:
            raise InputError(*e)
    return result


def _check_array_meta(path, shape, dtype, N):
    if len(shape) != 2:
        raise InputError(_KEY, f"{path}: expected a 2-D height array, got shape {tuple(shape)}")
    if tuple(shape) != (N, N):
        raise InputError(_KEY, f"{path}: expected an {N} x {N} height array (grid N = {N}), got "
                               f"{shape[0]} x {shape[1]}")
    if np.dtype(dtype).kind not in "fiu":
        raise InputError(_KEY, f"{path}: heights must be real numbers, got dtype {np.dtype(dtype)}")


def _read_npy(fft, path):
    try:
        arr = np.load(path, mmap_mode="r", allow_pickle=False)
    except Exception as e:  # not a .npy file, pickled objects, truncated header ...
        raise InputError(_KEY, f"{path}: cannot read as .npy ({type(e).__name__}: {e})".splitlines()[0])
    if not isinstance(arr, np.ndarray):
        raise InputError(_KEY, f"{path}: not a single .npy array")
    _check_array_meta(path, arr.shape, arr.dtype, fft.N)
    out = fft.real_array()
    try:
        out[...] = arr[fft.row_start:fft.row_stop]
    except Exception as e:  # truncated data
        raise InputError(_KEY, f"{path}: cannot read rows ({type(e).__name__}: {e})".splitlines()[0])
    return out


def _read_h5(fft, path, dataset):
    try:
        import h5py
    except ImportError:  # pragma: no cover
        raise InputError(_KEY, f"{path}: reading HDF5 needs h5py")
    try:
        fh = h5py.File(path, "r")
    except Exception as e:
        raise InputError(_KEY, f"{path}: cannot open as HDF5 ({type(e).__name__})")
    with fh:
        if dataset:
            ds = fh.get(dataset)
            if not isinstance(ds, h5py.Dataset):
                raise InputError(_KEY, f"{path}: no dataset {dataset!r}")
        else:
            found = []
            fh.visititems(lambda name, obj: found.append(name)
                          if isinstance(obj, h5py.Dataset) and obj.ndim == 2 else None)
            if len(found) != 1:
                what = "no 2-D dataset" if not found else f"several 2-D datasets ({', '.join(found[:5])})"
                raise InputError(_KEY, f"{path}: {what}; name one with the dataset option")
            ds = fh[found[0]]
        _check_array_meta(path, ds.shape, ds.dtype, fft.N)
        out = fft.real_array()
        try:
            out[...] = ds[fft.row_start:fft.row_stop, :]
        except Exception as e:
            raise InputError(_KEY, f"{path}: cannot read dataset ({type(e).__name__})")
    return out


def load(fft, path, dataset=None):
    """Read a surface (heights in m) from ``.npy`` or ``.h5``/``.hdf5``; each rank reads only its rows.

    ``.npy`` is memory-mapped (the full array is never loaded on any rank); for HDF5 ``dataset`` names
    the dataset, otherwise the file must contain exactly one 2-D dataset.  The array must be N x N
    (N = fft.N), real and finite.  Any other file is an instrument scan, read and made periodic by
    :func:`vecontact.io.topography.read_topography` (``dataset``: its channel).  Problems raise
    ``InputError("surface.file", ...)`` on all ranks.
    """
    path = os.fspath(path)

    def read():
        if not os.path.isfile(path):
            raise InputError(_KEY, f"{path}: no such file")
        ext = os.path.splitext(path)[1].lower()
        if ext == ".npy":
            return _read_npy(fft, path)
        if ext in (".h5", ".hdf5", ".he5"):
            return _read_h5(fft, path, dataset)
        from vecontact.io.topography import read_topography
        full = read_topography(path, dataset)[0]
        _check_array_meta(path, full.shape, full.dtype, fft.N)
        return np.ascontiguousarray(full[fft.row_start:fft.row_stop])

    h = _agree(fft.comm, read)

    def finite():
        if not np.isfinite(h).all():
            bad = np.argwhere(~np.isfinite(h))[0]
            raise InputError(_KEY, f"{path}: non-finite height at row {bad[0] + fft.row_start}, column {bad[1]}")

    _agree(fft.comm, finite)
    return h


# ---------------------------------------------------------------------------------------- statistics
def statistics(fft, h_local, L):
    """Surface statistics, identical on all ranks (dict of floats):

    mean      : <h> (m)
    hrms      : root-mean-square of h - <h> (m), = (sum_{q != 0} |h_q|^2)^1/2
    slope_rms : gbar = <|grad h|^2>^1/2 of the full 2-D gradient, computed spectrally
                (sum_q |q|^2 |h_q|^2)^1/2 (all modes counted, i.e. the slope of the band-limited
                trigonometric interpolant; the 1-D profile slope is a factor sqrt(2) smaller)
    min, max  : extreme heights (m)
    Does not count in ``fft.pairs`` (one forward transform, not solver work).
    """
    F = fft.forward(h_local)
    fft.n_forward -= 1
    _, _, q = fft.wavevectors(L)
    p = F.real ** 2 + F.imag ** 2
    w = fft.half_weights()
    s0 = np.sum(p.sum(axis=0) * w[0])
    s2 = np.sum((p * (q * q)).sum(axis=0) * w[0])
    dc = p[0, 0] if fft.col_start == 0 else 0.0
    tot = fft._allsum([s0 - dc, s2, np.sum(h_local)])
    N4 = float(fft.N) ** 4
    hmin = fft.comm.allreduce(float(np.min(h_local)), op=MPI.MIN)
    hmax = fft.comm.allreduce(float(np.max(h_local)), op=MPI.MAX)
    return dict(
        mean=float(tot[2]) / float(fft.N) ** 2,
        hrms=float(np.sqrt(max(tot[0], 0.0) / N4)),
        slope_rms=float(np.sqrt(tot[1] / N4)),
        min=hmin,
        max=hmax,
    )
