"""Two FFTW builds side by side in one process: the N x N real FFT pair (r2c + c2r, 2-D plans, 1 thread).

Usage (from the repository root):
    python benchmarks/fftw_builds.py LIB_A LIB_B [--sizes 2048,4096] [--rounds 8] [--per-round 4]
                                     [--planner measure|patient|estimate] [--single]

LIB_A, LIB_B: paths of two libfftw3.so (or libfftw3f.so with --single), e.g. the pyfftw wheel's
``pyfftw.libs/libfftw3-*.so.*`` and the one ./run builds (``~/.cache/vecontact/fftw-*/lib/libfftw3.so``).
Each is loaded with ctypes and RTLD_LOCAL, so both live in this process and neither is pyfftw's.
Rounds alternate (A then B, B then A, ...) so that the machine's drift falls on both; a pair's time
excludes the 1/N^2 rescaling between pairs.  Prints per size the version string of each library,
the round-trip error of one pair on the same data (a build that gives another answer is a bug), the
fastest and median pair in ms and the ratios B/A.  Figures: benchmarks/RESULTS.md, "FFTW with AVX2".
"""
from __future__ import annotations

import argparse
import ctypes
import time

import numpy as np

from vecontact.core.pfft import fftw_version

_FLAGS = {"measure": 0, "patient": 1 << 5, "estimate": 1 << 6}


class Build:
    """One libfftw3 (double) or libfftw3f (single) with an N x N r2c/c2r plan pair on its own arrays."""

    def __init__(self, path, N, single, planner):
        self.pre = "fftwf_" if single else "fftw_"
        self.real = np.float32 if single else np.float64
        cplx = np.complex64 if single else np.complex128
        self.lib = L = ctypes.CDLL(path, mode=ctypes.RTLD_LOCAL)
        self.version = fftw_version(L, self.pre)
        fn = self._fn
        for name in ("plan_dft_r2c_2d", "plan_dft_c2r_2d"):
            f = fn(name)
            f.restype = ctypes.c_void_p
            f.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_uint]
        fn("execute").argtypes = [ctypes.c_void_p]
        fn("malloc").restype = ctypes.c_void_p
        fn("malloc").argtypes = [ctypes.c_size_t]
        nr = N * N * np.dtype(self.real).itemsize
        nc = N * (N // 2 + 1) * np.dtype(cplx).itemsize
        pr, pc = fn("malloc")(nr), fn("malloc")(nc)   # FFTW's own alignment
        self.r = np.ctypeslib.as_array((ctypes.c_char * nr).from_address(pr)).view(self.real).reshape(N, N)
        self.N = N
        t = time.perf_counter()
        self.fwd = fn("plan_dft_r2c_2d")(N, N, pr, pc, _FLAGS[planner])
        self.bwd = fn("plan_dft_c2r_2d")(N, N, pc, pr, _FLAGS[planner])
        self.plan_seconds = time.perf_counter() - t
        self.execute = fn("execute")

    def _fn(self, name):
        return getattr(self.lib, self.pre + name)

    def pair(self):
        self.execute(self.fwd)
        self.execute(self.bwd)

    def rescale(self):
        self.r *= 1.0 / (self.N * self.N)

    def roundtrip_error(self, x):
        self.r[:] = x
        self.pair()
        self.rescale()
        return float(np.abs(self.r - x).max())


def compare(lib_a, lib_b, N, rounds, per_round, planner="measure", single=False):
    """Time both builds' pairs, rounds alternated; returns a dict of the figures (ms)."""
    a, b = Build(lib_a, N, single, planner), Build(lib_b, N, single, planner)
    x = np.random.default_rng(2).standard_normal((N, N)).astype(a.real)
    out = dict(N=N, single=single, version_a=a.version, version_b=b.version,
               plan_seconds_a=a.plan_seconds, plan_seconds_b=b.plan_seconds,
               error_a=a.roundtrip_error(x), error_b=b.roundtrip_error(x))
    times = {id(a): [], id(b): []}
    for k in range(rounds):
        for lib in ((a, b) if k % 2 == 0 else (b, a)):
            for _ in range(per_round):
                t = time.perf_counter()
                lib.pair()
                times[id(lib)].append(time.perf_counter() - t)
                lib.rescale()
    ta, tb = np.array(times[id(a)]) * 1e3, np.array(times[id(b)]) * 1e3
    out.update(min_a=ta.min(), median_a=float(np.median(ta)), min_b=tb.min(), median_b=float(np.median(tb)),
               ratio_min=tb.min() / ta.min(), ratio_median=float(np.median(tb) / np.median(ta)))
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("lib_a")
    ap.add_argument("lib_b")
    ap.add_argument("--sizes", default="2048,4096")
    ap.add_argument("--rounds", type=int, default=8)
    ap.add_argument("--per-round", type=int, default=4)
    ap.add_argument("--planner", choices=sorted(_FLAGS), default="measure")
    ap.add_argument("--single", action="store_true", help="float32 (libfftw3f) instead of float64")
    args = ap.parse_args(argv)
    for N in (int(s) for s in args.sizes.split(",")):
        r = compare(args.lib_a, args.lib_b, N, args.rounds, args.per_round, args.planner, args.single)
        print(f"N={N} {'float' if args.single else 'double'}: A {r['version_a']}, B {r['version_b']}; "
              f"round-trip error A {r['error_a']:.2e} B {r['error_b']:.2e}")
        print(f"  A min {r['min_a']:.2f} median {r['median_a']:.2f} ms | B min {r['min_b']:.2f} median "
              f"{r['median_b']:.2f} ms | B/A min {r['ratio_min']:.3f} median {r['ratio_median']:.3f}",
              flush=True)


if __name__ == "__main__":
    main()
