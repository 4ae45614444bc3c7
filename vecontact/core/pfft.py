"""Distributed real 2-D FFT on an N x N periodic grid (slab decomposition, MPI + FFTW).

Conventions (see docs/conventions.md §1)
------------------------------------------
* Real space: array ``f[i, j]`` at x = (i, j) L/N. Axis 0 (x, the sliding direction, index i) is split
  by contiguous row blocks across ranks, axis 1 (y) is whole on every rank:
  ``local_real_shape = (row_stop - row_start, N)``.
* Fourier space: exactly numpy's ``rfft2`` layout, split by ky columns:
  ``F_local = numpy.fft.rfft2(f_full)[:, col_start:col_stop]``, ``local_fourier_shape = (N, ncols)``.
  Axis 0 is kx in numpy ``fftfreq`` order (``kx = 0, 1, .., -N/2, .., -1``, integers), axis 1 is
  ky = col_start .. col_stop-1 (global ky range 0 .. N//2, i.e. N//2+1 columns).
  Wavevector q = (2 pi / L) (kx, ky) in 1/m.
* ``forward`` is unnormalised like ``numpy.fft.rfft2`` (so the Fourier coefficient of docs/conventions.md is
  h_q = forward(h) / N^2); ``backward`` is ``numpy.fft.irfft2`` (includes the 1/N^2).

Algorithm: forward = r2c along y on the local rows -> global transpose (MPI ``Alltoallw`` with subarray
datatypes straight from/to the FFTW buffers, no packing) -> c2c along x on the local ky columns
(a strided batch, FFTW handles the layout).  Backward is the reverse.  With one rank no communication
happens at all and a single 2-D FFTW r2c/c2r plan is used (same layout).
All buffers and FFTW plans are created in ``__init__``; ``forward/backward/apply`` allocate nothing
when output arrays are passed (``out=None`` allocates the result array, for convenience only).
"""
from __future__ import annotations

import ctypes
import hashlib
import os
import pickle
import platform
import tempfile
import time

import numpy as np
import pyfftw
from mpi4py import MPI

from vecontact.core.pages import huge_page_advice

# wall seconds spent in SlabFFT.apply by this process, all instances (benchmarks read it: apply_seconds)
_APPLY_SECONDS = [0.0]


def apply_seconds():
    """Wall seconds this process has spent in ``SlabFFT.apply`` so far, over every SlabFFT (coarse grids
    included): with the pair counters, what a solve's FFT pairs cost inside the solve."""
    return _APPLY_SECONDS[0]


# precision -> (real dtype, complex dtype, MPI complex type (C name, Fortran name))
_DTYPES = {
    "double": (np.dtype(np.float64), np.dtype(np.complex128), ("C_DOUBLE_COMPLEX", "DOUBLE_COMPLEX")),
    "single": (np.dtype(np.float32), np.dtype(np.complex64), ("C_FLOAT_COMPLEX", "COMPLEX")),
}

_FLAGS = {
    "estimate": "FFTW_ESTIMATE",
    "measure": "FFTW_MEASURE",
    "patient": "FFTW_PATIENT",
    "exhaustive": "FFTW_EXHAUSTIVE",
}


def split_range(n, size, rank):
    """Contiguous block split of ``range(n)``: the first ``n % size`` ranks get one more element."""
    base, rem = divmod(n, size)
    start = rank * base + min(rank, rem)
    return start, start + base + (1 if rank < rem else 0)


def column_split(nc, size):
    """Split of the ``nc`` ky columns: like ``split_range`` but no rank gets a multiple of 32 columns
    (when avoidable), because the row stride of the (N, ncols) Fourier slab would then be a multiple of
    512 bytes and the strided c2c along kx suffers cache-set aliasing (measured 3.5x slower at
    N=4096 on 2 ranks with 1024 columns).  Returns the list of (start, stop) for all ranks."""
    counts = [split_range(nc, size, r)[1] - split_range(nc, size, r)[0] for r in range(size)]
    def bad(c):
        return c >= 32 and c % 32 == 0

    for i in range(size):
        if not bad(counts[i]):
            continue
        for j in (i + 1, i - 1):
            if 0 <= j < size:
                if counts[j] > 1 and not bad(counts[j] - 1):
                    counts[i] += 1
                    counts[j] -= 1
                    break
                if not bad(counts[j] + 1):
                    counts[i] -= 1
                    counts[j] += 1
                    break
    starts = np.concatenate([[0], np.cumsum(counts)]).astype(int)
    return [(int(starts[r]), int(starts[r + 1])) for r in range(size)]


def fftw_version(lib=None, prefix="fftw_"):
    """The version string of an FFTW library, with its SIMD codelets (e.g.
    ``fftw-3.3.10-sse2-avx-avx2-avx2_128``; ./run builds that one on x86-64, README "Install").

    ``lib`` is a ``ctypes.CDLL``; by default the FFTW pyfftw runs on. ``prefix`` is ``"fftw_"``
    for double precision, ``"fftwf_"`` for single."""
    try:
        if lib is None:
            lib = ctypes.CDLL(pyfftw.pyfftw.__file__)
        # fftw_version is a char array (not a pointer) in libfftw3
        return (ctypes.c_char * 64).in_dll(lib, prefix + "version").value.decode()
    except (OSError, ValueError, AttributeError):
        return "version not exported"


def default_wisdom_file():
    """``~/.cache/vecontact/fftw-wisdom-<hash>.pkl``; the hash covers host, CPU, pyfftw and FFTW
    (a build's wisdom does not fit another's codelets)."""
    key = "|".join([platform.node(), platform.machine(), platform.processor(), pyfftw.__version__,
                    fftw_version()])
    h = hashlib.sha1(key.encode()).hexdigest()[:12]
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "vecontact", f"fftw-wisdom-{h}.pkl")


def _load_wisdom(path):
    try:
        with open(path, "rb") as fh:
            wis = pickle.load(fh)
        pyfftw.import_wisdom(tuple(wis))
    except Exception:  # missing/corrupt/unreadable: never fatal
        pass


def _save_wisdom(path, wisdoms):
    try:
        for w in wisdoms:
            pyfftw.import_wisdom(tuple(w))
        data = pickle.dumps(pyfftw.export_wisdom())
        d = os.path.dirname(path) or "."
        os.makedirs(d, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=d, prefix=".wisdom-")
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.replace(tmp, path)
    except Exception:  # unwritable cache: never fatal
        pass


def _run(plan, inp, out):
    """Execute an FFTW plan on new arrays (same shape/strides/alignment as planned; checked by caller)."""
    plan.update_arrays(inp, out)
    plan.execute()


class SlabFFT:
    """Distributed real FFT of an N x N grid on communicator ``comm`` (see module docstring).

    Parameters
    ----------
    comm : mpi4py communicator (``MPI.COMM_WORLD`` or a sub-communicator)
    N : grid size (any N >= 2; 1 <= comm.size <= N//2 is the supported range, up to
        min(N, N//2+1) ranks actually work)
    threads : FFTW threads per rank
    planner : "estimate" | "measure" | "patient" | "exhaustive"
    wisdom_file : path of the FFTW wisdom pickle; None -> ``default_wisdom_file()``; False/"" -> no
        wisdom file.  Loaded before planning, merged over ranks and saved (by rank 0) after planning;
        failures to read or write are silently ignored.

    precision : "double" (float64 / complex128 arrays, the default) or "single" (float32 / complex64:
        half the memory traffic, about 1.7-2x faster pairs; relative rounding ~6e-8).  ``single()`` gives
        a double-precision SlabFFT's single-precision twin.

    Counters: ``n_forward``, ``n_backward`` (standalone calls) and ``n_apply`` (calls of ``apply`` and of
    what is built on it: ``gradient``).  ``pairs = n_apply + min(n_forward, n_backward)`` is the number
    of complete forward+backward pairs (an int); ``transforms = 2 n_apply + n_forward + n_backward``.
    Both include the single-precision twin's (its pairs count as pairs); ``single_transforms`` is the
    twin's share.  Assigning ``fft.pairs = 0`` (or calling ``reset_counters()``) resets all counters.
    """

    def __init__(self, comm, N, threads=1, planner="measure", wisdom_file=None, precision="double"):
        self.comm = comm
        self.N = N = int(N)
        self.rank = comm.rank
        self.size = P = comm.size
        if N < 2:
            raise ValueError("SlabFFT needs N >= 2")
        if P > min(N, N // 2 + 1):
            raise ValueError(f"SlabFFT: {P} ranks is too many for N = {N} (at most N//2 = {N // 2})")
        if planner not in _FLAGS:
            raise ValueError(f"planner must be one of {sorted(_FLAGS)}, got {planner!r}")
        if precision not in _DTYPES:
            raise ValueError(f"precision must be one of {sorted(_DTYPES)}, got {precision!r}")
        self.precision = precision
        self.real_dtype, self.complex_dtype, mpi_complex = _DTYPES[precision]
        self._single = None
        self.threads = int(threads)
        self.planner = planner
        self.Nc = Nc = N // 2 + 1
        self._rows = [split_range(N, P, r) for r in range(P)]
        self._cols = column_split(Nc, P)
        self.row_start, self.row_stop = self._rows[self.rank]
        self.col_start, self.col_stop = self._cols[self.rank]
        self.nrows = self.row_stop - self.row_start
        self.ncols = self.col_stop - self.col_start
        self.local_real_shape = (self.nrows, N)
        self.local_fourier_shape = (N, self.ncols)

        kx = np.fft.fftfreq(N, 1.0 / N).round().astype(np.int64)
        self.kx = kx.reshape(N, 1)
        self.ky = np.arange(self.col_start, self.col_stop, dtype=np.int64).reshape(1, self.ncols)
        self.norm = 1.0 / (float(N) * float(N))    # the backward transform's normalisation (``apply``'s normalised)

        self.n_forward = 0
        self.n_backward = 0
        self.n_apply = 0
        self._grad_cache = {}

        if wisdom_file is None:
            wisdom_file = default_wisdom_file()
        self.wisdom_file = wisdom_file or None
        if self.wisdom_file:
            _load_wisdom(self.wisdom_file)

        flags = (_FLAGS[planner],)
        kw = dict(flags=flags, threads=self.threads)
        # work buffers (all aligned), on huge pages whatever the caller's advice: they live as long as
        # the SlabFFT, and 4 KiB pages made the 4096^2 pair 1.2x slower (RESULTS.md, "Huge pages")
        with huge_page_advice(True):
            self._rbuf = pyfftw.empty_aligned(self.local_real_shape, dtype=self.real_dtype)
            self._B = pyfftw.empty_aligned(self.local_fourier_shape, dtype=self.complex_dtype)
            self._A = None if P == 1 else pyfftw.empty_aligned((self.nrows, Nc), dtype=self.complex_dtype)
        if P == 1:
            # FFTW_MEASURE overwrites the arrays while planning: fine, they are scratch.
            self._p_fwd = pyfftw.FFTW(self._rbuf, self._B, axes=(0, 1), direction="FFTW_FORWARD", **kw)
            self._p_bwd = pyfftw.FFTW(self._B, self._rbuf, axes=(0, 1), direction="FFTW_BACKWARD", **kw)
        else:
            self._p_r2c = pyfftw.FFTW(self._rbuf, self._A, axes=(1,), direction="FFTW_FORWARD", **kw)
            self._p_c2r = pyfftw.FFTW(self._A, self._rbuf, axes=(1,), direction="FFTW_BACKWARD", **kw)
            # c2c along kx (axis 0, a strided batch over the local ky columns): IN-PLACE plans only,
            # FFTW is 3-5x slower on the out-of-place strided variant (measured).
            self._p_xf_ip = pyfftw.FFTW(self._B, self._B, axes=(0,), direction="FFTW_FORWARD", **kw)
            self._p_xb_ip = pyfftw.FFTW(self._B, self._B, axes=(0,), direction="FFTW_BACKWARD", **kw)
            self._build_types(mpi_complex)
        self._real_align = self._rbuf.ctypes.data % pyfftw.simd_alignment == 0
        if self.wisdom_file:
            wis = comm.gather(pyfftw.export_wisdom(), root=0)
            if self.rank == 0:
                _save_wisdom(self.wisdom_file, wis)

    # ------------------------------------------------------------------ transpose machinery
    def _build_types(self, mpi_complex):
        """Subarray datatypes: rows-slab A (nrows, Nc) <-> column-slab B (N, ncols) of the complex type."""
        Nc, N = self.Nc, self.N
        c_type, f_type = mpi_complex
        base = getattr(MPI, c_type)
        if base == MPI.DATATYPE_NULL:
            base = getattr(MPI, f_type)
        self._types = []
        tA, tB = [], []
        for r in range(self.size):
            c0, c1 = self._cols[r]
            r0, r1 = self._rows[r]
            # what I hold of rank r's columns (in A) and what rank r holds of my columns (into B)
            ta = base.Create_subarray([self.nrows, Nc], [self.nrows, c1 - c0], [0, c0]).Commit()
            tb = base.Create_subarray([N, self.ncols], [r1 - r0, self.ncols], [r0, 0]).Commit()
            tA.append(ta)
            tB.append(tb)
        self._types = tA + tB
        ones = [1] * self.size
        zeros = [0] * self.size
        self._msgA = [self._A, (ones, zeros), tA]
        self._msgB = [self._B, (ones, zeros), tB]

    def _a2b(self):
        self.comm.Alltoallw(self._msgA, self._msgB)

    def _b2a(self):
        self.comm.Alltoallw(self._msgB, self._msgA)

    def free(self):
        """Free the MPI datatypes (optional; also done at garbage collection)."""
        for t in getattr(self, "_types", []):
            try:
                if t != MPI.DATATYPE_NULL:
                    t.Free()
            except Exception:
                pass
        self._types = []

    def __del__(self):
        try:
            if not MPI.Is_finalized():
                self.free()
        except Exception:
            pass

    # ------------------------------------------------------------------ helpers
    def _ok_real(self, a):
        return (isinstance(a, np.ndarray) and a.dtype == self.real_dtype and a.shape == self.local_real_shape
                and a.flags.c_contiguous and a.ctypes.data % pyfftw.simd_alignment == 0)

    def _ok_fourier(self, a):
        return (isinstance(a, np.ndarray) and a.dtype == self.complex_dtype and a.shape == self.local_fourier_shape
                and a.flags.c_contiguous and a.ctypes.data % pyfftw.simd_alignment == 0)

    def _check_real(self, a, name="real_in"):
        if not isinstance(a, np.ndarray) or a.shape != self.local_real_shape:
            raise ValueError(f"{name}: expected local real shape {self.local_real_shape}, got "
                             f"{getattr(a, 'shape', type(a))}")

    def _check_fourier(self, a, name="fourier_in"):
        if not isinstance(a, np.ndarray) or a.shape != self.local_fourier_shape:
            raise ValueError(f"{name}: expected local Fourier shape {self.local_fourier_shape}, got "
                             f"{getattr(a, 'shape', type(a))}")

    def real_array(self):
        """New aligned zero array of ``local_real_shape`` (float64; float32 in single precision)."""
        return pyfftw.zeros_aligned(self.local_real_shape, dtype=self.real_dtype)

    def fourier_array(self):
        """New aligned zero array of ``local_fourier_shape`` (complex128; complex64 in single precision)."""
        return pyfftw.zeros_aligned(self.local_fourier_shape, dtype=self.complex_dtype)

    def single(self):
        """The single-precision twin (same communicator, grid, split and planner; made on first use,
        collective then).  Its transforms count in this SlabFFT's counters."""
        if self.precision == "single":
            return self
        if self._single is None:
            self._single = SlabFFT(self.comm, self.N, threads=self.threads, planner=self.planner,
                                   wisdom_file=self.wisdom_file or False, precision="single")
        return self._single

    @property
    def single_transforms(self):
        """Transforms done by the single-precision twin (included in ``transforms``)."""
        return 0 if self._single is None else self._single.transforms

    @property
    def pairs(self):
        own = self.n_apply + min(self.n_forward, self.n_backward)
        return own + (0 if self._single is None else self._single.pairs)

    @pairs.setter
    def pairs(self, value):
        self.reset_counters()
        self.n_apply = int(value)

    @property
    def transforms(self):
        return 2 * self.n_apply + self.n_forward + self.n_backward + self.single_transforms

    def reset_counters(self):
        self.n_apply = self.n_forward = self.n_backward = 0
        if self._single is not None:
            self._single.reset_counters()

    def release_arrays(self):
        """Point the plans back at this SlabFFT's own buffers (and the twin's at its own).  An FFTW plan
        keeps the arrays of its last execution alive, and those are the caller's: a solve's fields,
        a coarse level's operator; solve_contact calls this when it is done with a grid."""
        if self.size == 1:
            self._p_fwd.update_arrays(self._rbuf, self._B)
            self._p_bwd.update_arrays(self._B, self._rbuf)
        else:
            self._p_r2c.update_arrays(self._rbuf, self._A)
            self._p_c2r.update_arrays(self._A, self._rbuf)
            self._p_xf_ip.update_arrays(self._B, self._B)
        if self._single is not None:
            self._single.release_arrays()

    # ------------------------------------------------------------------ core transforms
    def _forward_into(self, real_in, dst):
        """Forward transform of real_in into ``dst`` (aligned C-contiguous Fourier array, may be B)."""
        src = real_in if self._ok_real(real_in) else self._rbuf
        if src is self._rbuf:
            np.copyto(self._rbuf, real_in)
        if self.size == 1:
            _run(self._p_fwd, src, dst)
        else:
            _run(self._p_r2c, src, self._A)
            if dst is self._B:
                self._a2b()
            else:
                self.comm.Alltoallw(self._msgA, [dst, self._msgB[1], self._msgB[2]])
            _run(self._p_xf_ip, dst, dst)

    def _backward_from_B(self, real_out, scaled, scale=1.0):
        """Backward transform of B (destroyed), times ``scale`` / N^2 unless ``scaled``. P > 1: B must not
        be x-transformed yet."""
        dst = real_out if self._ok_real(real_out) else self._rbuf
        if self.size == 1:
            _run(self._p_bwd, self._B, dst)
        else:
            self._p_xb_ip.execute()
            self._b2a()
            _run(self._p_c2r, self._A, dst)
        if not scaled:
            np.multiply(dst, self.norm * scale, out=real_out)     # x * 1.0 is x: scale 1 changes nothing
        elif dst is not real_out:
            np.copyto(real_out, dst)

    def forward(self, real_in, fourier_out=None):
        """Unnormalised forward transform (like ``numpy.fft.rfft2``) of the local rows ``real_in``.

        Returns the local Fourier columns ``fourier_out`` (allocated if None); h_q = forward(h)/N^2.
        ``real_in`` is not modified.  No allocation when ``fourier_out`` is given.
        """
        self._check_real(real_in)
        if fourier_out is None:
            fourier_out = self.fourier_array()
        else:
            self._check_fourier(fourier_out, "fourier_out")
        if self._ok_fourier(fourier_out):
            self._forward_into(real_in, fourier_out)
        else:
            self._forward_into(real_in, self._B)
            np.copyto(fourier_out, self._B)
        self.n_forward += 1
        return fourier_out

    def backward(self, fourier_in, real_out=None):
        """Inverse transform (like ``numpy.fft.irfft2``, includes 1/N^2); ``fourier_in`` is preserved.

        The imaginary parts of the self-conjugate entries (ky = 0 and ky = N/2 columns) are handled like
        numpy/FFTW c2r: the result is the real field whose half spectrum is Hermitian-projected.
        No allocation when ``real_out`` is given.
        """
        self._check_fourier(fourier_in)
        if real_out is None:
            real_out = self.real_array()
        else:
            self._check_real(real_out, "real_out")
        np.multiply(fourier_in, self.norm, out=self._B)  # the copy c2r needs anyway, with the 1/N^2
        self._backward_from_B(real_out, scaled=True)
        self.n_backward += 1
        return real_out

    def apply(self, real_in, multiplier, real_out=None, scale=1.0, normalised=False):
        """``scale * backward(multiplier * forward(real_in))`` with no temporaries; counts one pair.

        ``multiplier`` is complex or real, broadcastable to ``local_fourier_shape`` (e.g. a full local
        array, or shape (N, 1) for a function of kx only).  ``real_out`` may be ``real_in``.
        ``scale`` (a number) rides on the 1/N^2 pass: a multiple of a stored multiplier without a
        whole-grid copy of it.  ``normalised``: ``real_in`` already carries the 1/N^2 (``norm``; the
        caller folded it in where it writes its input, subset.Grid): no pass over the output at all,
        and ``scale`` must be 1.
        Use ``hermitian_fix`` on multipliers that are not Hermitian on the x-Nyquist row.
        """
        self._check_real(real_in)
        if real_out is None:
            real_out = self.real_array()
        else:
            self._check_real(real_out, "real_out")
        return self._pair(self, real_in, multiplier, real_out, scale, normalised)

    def apply_across(self, twin, real_in, multiplier, real_out, scale=1.0, normalised=False):
        """``apply`` with the forward transform in this SlabFFT's precision and the backward in ``twin``'s
        (its other-precision twin: same grid and split).  ``real_in`` and
        ``real_out`` must be the two precisions' local real arrays, ``multiplier`` is applied in the wider
        of its and the spectrum's precision.  Where a product's input must not be rounded to float32 but
        its output may be, or the other way round (solver/subset.py, ``Mixed``).  The pair counts on the
        double-precision SlabFFT (not in ``single_transforms``)."""
        dtypes = (getattr(real_in, "dtype", None), getattr(real_out, "dtype", None))
        if twin.local_fourier_shape != self.local_fourier_shape or dtypes != (self.real_dtype, twin.real_dtype):
            raise ValueError("apply_across: real_in / real_out must be this SlabFFT's and its twin's arrays")
        self._check_real(real_in)
        self._check_real(real_out, "real_out")
        return self._pair(twin, real_in, multiplier, real_out, scale, normalised)

    def _pair(self, twin, real_in, multiplier, real_out, scale, normalised):
        """The pair of ``apply`` (``twin`` is self) and ``apply_across``: forward here, multiply into the
        twin's B, backward there; timed, and counted on the double-precision one of the two."""
        if normalised and scale != 1.0:
            raise ValueError("apply: normalised input takes no scale (fold it into the input)")
        t0 = time.perf_counter()
        self._forward_into(real_in, self._B)
        np.multiply(self._B, multiplier, out=twin._B, casting="same_kind")
        twin._backward_from_B(real_out, scaled=normalised, scale=scale)
        _APPLY_SECONDS[0] += time.perf_counter() - t0
        (twin if twin.precision == "double" else self).n_apply += 1
        return real_out

    def time_pair(self, repeats=3):
        """The machine's pace now: wall seconds of one distributed pair (``apply`` in place, unit
        multiplier, a fixed field) as (fastest, median) of ``repeats`` pairs timed between barriers
        after an untimed one.  Collective; every rank returns rank 0's figures.  The pairs count
        neither in the pair counters nor in ``apply_seconds``; the two arrays are freed after.
        benchmarks/solver.py and peers.py call it the raw pair; the farm times one after each case
        (``raw_pair_seconds`` in /diagnostics)."""
        if repeats < 1:
            raise ValueError(f"time_pair: repeats must be >= 1, got {repeats}")
        counters, spent = (self.n_apply, self.n_forward, self.n_backward), _APPLY_SECONDS[0]
        a = self.real_array()
        a[...] = np.arange(a.shape[-1], dtype=a.dtype) % 7     # any field: FFTW's time does not depend on it
        unit = self.fourier_array()
        unit[...] = 1.0
        self.apply(a, unit, a)
        times = []
        for _ in range(repeats):
            self.comm.Barrier()
            t0 = time.perf_counter()
            self.apply(a, unit, a)
            self.comm.Barrier()
            times.append(time.perf_counter() - t0)
        self.n_apply, self.n_forward, self.n_backward = counters
        _APPLY_SECONDS[0] = spent
        self.release_arrays()
        return self.comm.bcast((min(times), float(np.median(times))), root=0)

    # ------------------------------------------------------------------ wavevectors & multipliers
    def wavevectors(self, L):
        """(qx, qy, q) in 1/m: qx shape (N, 1), qy shape (1, ncols), q = |q| shape local_fourier_shape."""
        dq = 2.0 * np.pi / float(L)
        qx = dq * self.kx.astype(np.float64)
        qy = dq * self.ky.astype(np.float64)
        return qx, qy, np.sqrt(qx * qx + qy * qy)

    def hermitian_fix(self, multiplier):
        """Make a multiplier valid for real -> real operators (docs/conventions.md §1).

        On the x-Nyquist row (kx = -N/2, N even) the multiplier is replaced by its real part (in place
        when ``multiplier`` is a full-height complex array, otherwise a fixed copy broadcast to
        ``local_fourier_shape`` is made).  Returns the multiplier.
        """
        m = np.asarray(multiplier)
        if self.N % 2 or not np.iscomplexobj(m):
            return multiplier
        if m.ndim == 2 and m.shape[0] == self.N and m.flags.writeable:
            m[self.N // 2] = m[self.N // 2].real
            return m
        m = np.array(np.broadcast_to(m, self.local_fourier_shape), dtype=np.complex128)
        m[self.N // 2] = m[self.N // 2].real
        return m

    def gradient(self, real_in, L, axis, real_out=None):
        """Spectral derivative d/dx (axis 0) or d/dy (axis 1) of a real field, L the period (m).

        The Nyquist mode of the differentiated axis (N even) is zeroed.  Counts one pair.
        """
        if axis not in (0, 1):
            raise ValueError("axis must be 0 (x) or 1 (y)")
        key = (float(L), axis)
        m = self._grad_cache.get(key)
        if m is None:
            qx, qy, _ = self.wavevectors(L)
            if axis == 0:
                m = 1j * qx
                if self.N % 2 == 0:
                    m[self.N // 2] = 0.0
            else:
                m = 1j * qy
                if self.N % 2 == 0:
                    m[self.ky == self.N // 2] = 0.0
            self._grad_cache = {key: m} if len(self._grad_cache) > 8 else self._grad_cache
            self._grad_cache[key] = m
        return self.apply(real_in, m, real_out)

    # ------------------------------------------------------------------ reductions
    def _allsum(self, values):
        """Sum of float64 arrays over ranks, bitwise identical on all ranks (reduce + bcast)."""
        v = np.ascontiguousarray(values, dtype=np.float64)
        if self.size == 1:
            return v.copy()
        out = np.empty_like(v)
        self.comm.Reduce(v, out, op=MPI.SUM, root=0)
        self.comm.Bcast(out, root=0)
        return out

    def half_weights(self):
        """Weights (1, ncols) of the stored half spectrum in full-spectrum sums: 1 for ky = 0 and
        ky = N/2 (N even), 2 otherwise."""
        w = np.full((1, self.ncols), 2.0)
        w[self.ky == 0] = 1.0
        if self.N % 2 == 0:
            w[self.ky == self.N // 2] = 1.0
        return w

    def parseval(self, fourier_in):
        """sum over the FULL spectrum of |a_q|^2 / N^4 (= mean f^2 for f = backward(a)), allreduced."""
        self._check_fourier(fourier_in)
        a2 = fourier_in.real ** 2 + fourier_in.imag ** 2
        loc = float(np.sum(a2.sum(axis=0) * self.half_weights()[0]))
        return float(self._allsum([loc])[0]) / float(self.N) ** 4

    def sum(self, real_in):
        """Global sum of a distributed real field (identical on all ranks)."""
        return float(self._allsum([np.sum(real_in, dtype=np.float64)])[0])

    def mean(self, real_in):
        """Global mean of a distributed real field (identical on all ranks)."""
        return self.sum(real_in) / (float(self.N) * float(self.N))

    # ------------------------------------------------------------------ gather / scatter
    def _counts(self):
        return [(r1 - r0) * self.N for r0, r1 in self._rows], [r0 * self.N for r0, _ in self._rows]

    def gather(self, real_in, root=0):
        """Full N x N float64 array on ``root`` (None elsewhere). For tests and small grids."""
        self._check_real(real_in)
        src = np.ascontiguousarray(real_in, dtype=np.float64)
        if self.size == 1:
            return src.copy()
        counts, displs = self._counts()
        full = np.empty((self.N, self.N)) if self.rank == root else None
        self.comm.Gatherv(src, [full, counts, displs, MPI.DOUBLE] if self.rank == root else None, root=root)
        return full

    def scatter(self, full, root=0):
        """Distribute an N x N array given on ``root`` (ignored elsewhere); returns the local rows."""
        out = self.real_array()
        if self.size == 1:
            out[...] = full
            return out
        counts, displs = self._counts()
        send = None
        if self.rank == root:
            full = np.ascontiguousarray(full, dtype=np.float64)
            if full.shape != (self.N, self.N):
                raise ValueError(f"scatter: expected ({self.N}, {self.N}), got {full.shape}")
            send = [full, counts, displs, MPI.DOUBLE]
        self.comm.Scatterv(send, out, root=root)
        return out

    # ------------------------------------------------------------------ spectra
    def radial_psd(self, real_in, L, nbins=None, fourier=None):
        """Radially averaged PSD estimate (Persson convention), identical on all ranks.

        C_q = |h_q|^2 / (2 pi / L)^2 with h_q = forward(h)/N^2, averaged over all modes of the FULL
        spectrum in annuli of |q|.  Default bins: unit width in q_L = 2pi/L centred on k = 1 .. N//2
        (edges (k -/+ 1/2) q_L); ``nbins`` gives that many equal-width bins over [q_L/2, (N//2 + 1/2) q_L].
        Returns (q_centers, C): q_centers is the mean |q| of the modes in each bin (1/m), C in m^4;
        empty bins are dropped.  ``fourier`` may pass forward(real_in) to skip the transform.
        """
        N = self.N
        dq = 2.0 * np.pi / float(L)
        F = self.forward(real_in) if fourier is None else fourier
        if fourier is None:
            self.n_forward -= 1  # analysis, not solver work
        _, _, q = self.wavevectors(L)
        k = q / dq
        kmax = N // 2 + 0.5
        if nbins is None:
            nb = N // 2
        else:
            nb = int(nbins)
        edges = np.linspace(0.5, kmax, nb + 1)
        idx = np.searchsorted(edges, k, side="right") - 1
        w = np.broadcast_to(self.half_weights(), k.shape)
        valid = (idx >= 0) & (idx < nb)
        p = (F.real ** 2 + F.imag ** 2) * (1.0 / float(N) ** 4 / dq ** 2)
        iv, wv = idx[valid], w[valid]
        loc = np.concatenate([
            np.bincount(iv, weights=wv, minlength=nb),
            np.bincount(iv, weights=wv * k[valid], minlength=nb),
            np.bincount(iv, weights=wv * p[valid], minlength=nb),
        ])
        tot = self._allsum(loc)
        cnt, ks, cs = tot[:nb], tot[nb:2 * nb], tot[2 * nb:]
        ok = cnt > 0
        return ks[ok] / cnt[ok] * dq, cs[ok] / cnt[ok]
