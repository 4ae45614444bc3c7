"""SlabFFT vs numpy on whatever number of ranks this runs on (imported by tests/test_pfft.py for 1 rank,
run under mpiexec -n 2/3/4 by the same tests).  Exits non-zero (MPI Abort) on failure."""
import sys

import numpy as np
from mpi4py import MPI

from vecontact.core.pfft import SlabFFT

SIZES = (8, 9, 15, 16, 30, 64)


def rel(a, b):
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


def check_one(comm, N, tol=1e-12):
    fft = SlabFFT(comm, N, planner="estimate", wisdom_file=False)
    rs, re_, cs, ce = fft.row_start, fft.row_stop, fft.col_start, fft.col_stop
    # decomposition bookkeeping
    assert fft.local_real_shape == (re_ - rs, N)
    assert fft.local_fourier_shape == (N, ce - cs)
    rows = comm.allgather((rs, re_))
    cols = comm.allgather((cs, ce))
    assert rows[0][0] == 0 and rows[-1][1] == N and all(rows[i][1] == rows[i + 1][0] for i in range(len(rows) - 1))
    assert cols[0][0] == 0 and cols[-1][1] == N // 2 + 1 and all(cols[i][1] == cols[i + 1][0] for i in range(len(cols) - 1))
    assert np.array_equal(np.broadcast_to(fft.kx, (N, 1)).ravel(), np.round(np.fft.fftfreq(N, 1.0 / N)).astype(int))
    assert np.array_equal(fft.ky.ravel(), np.arange(cs, ce))

    rng = np.random.default_rng(1000 + N)  # same full field on every rank
    full = rng.standard_normal((N, N))
    mult = rng.standard_normal((N, N // 2 + 1)) + 1j * rng.standard_normal((N, N // 2 + 1))
    loc = fft.real_array()
    loc[...] = full[rs:re_]
    ref = np.fft.rfft2(full)

    F = fft.forward(loc)
    assert rel(F, ref[:, cs:ce]) < tol, ("forward", N, rel(F, ref[:, cs:ce]))
    # non-aligned / non-contiguous inputs and outputs take the copy path
    F2 = np.zeros((N, ce - cs), complex)
    fft.forward(np.array(loc, order="F"), F2)
    assert rel(F2, ref[:, cs:ce]) < tol
    Fkeep = F.copy()
    back = fft.backward(F)
    assert np.array_equal(F, Fkeep), "backward destroyed its input"
    assert rel(back, full[rs:re_]) < tol, ("roundtrip", N)
    # backward of a general (non-Hermitian-consistent) half spectrum behaves like numpy irfft2
    G = mult[:, cs:ce].copy()
    out = np.zeros((re_ - rs, N))
    fft.backward(G, out)
    assert rel(out, np.fft.irfft2(mult, s=(N, N))[rs:re_]) < tol, ("backward", N)

    # apply
    refa = np.fft.irfft2(ref * mult, s=(N, N))
    a = fft.apply(loc, mult[:, cs:ce])
    assert rel(a, refa[rs:re_]) < tol, ("apply", N)
    b = loc.copy()
    fft.apply(b, mult[:, cs:ce], b)  # in place
    assert rel(b, refa[rs:re_]) < tol
    # broadcast multiplier (function of kx only) and real multiplier
    mx = mult[:, :1].real.copy()
    a = fft.apply(loc, mx)
    assert rel(a, np.fft.irfft2(ref * mx, s=(N, N))[rs:re_]) < tol

    # hermitian_fix: after the fix the operator is real->real and matches numpy on the fixed multiplier
    m = mult[:, cs:ce].copy()
    fixed = fft.hermitian_fix(m)
    if N % 2 == 0:
        assert np.all(fixed[N // 2].imag == 0)
        mf = mult.copy()
        mf[N // 2] = mf[N // 2].real
        assert rel(fft.apply(loc, fixed), np.fft.irfft2(ref * mf, s=(N, N))[rs:re_]) < tol
    else:
        assert np.array_equal(fixed, mult[:, cs:ce])

    # gradient vs analytic
    L = 2.5e-5
    x = (np.arange(N) * L / N)[:, None]
    y = (np.arange(N) * L / N)[None, :]
    k1, k2 = 2 * np.pi * 3 / L, 2 * np.pi * 2 / L
    f = np.sin(k1 * x + 0.3) * np.cos(k2 * y - 0.7)
    fl = fft.real_array()
    fl[...] = f[rs:re_]
    gx = fft.gradient(fl, L, 0)
    gy = fft.gradient(fl, L, 1)
    ex = (k1 * np.cos(k1 * x + 0.3) * np.cos(k2 * y - 0.7))[rs:re_]
    ey = (-k2 * np.sin(k1 * x + 0.3) * np.sin(k2 * y - 0.7))[rs:re_]
    assert np.max(np.abs(gx - ex)) < 1e-12 * k1 and np.max(np.abs(gy - ey)) < 1e-12 * k2, ("gradient", N)
    if N % 2 == 0:  # Nyquist modes are zeroed: derivative of cos(pi i) along x is 0
        ny = fft.real_array()
        ny[...] = np.cos(np.pi * np.arange(rs, re_))[:, None] + np.cos(np.pi * np.arange(N))[None, :]
        assert np.max(np.abs(fft.gradient(ny, L, 0))) < 1e-9 and np.max(np.abs(fft.gradient(ny, L, 1))) < 1e-9

    # reductions
    Ff = fft.forward(loc)
    p = fft.parseval(Ff)
    assert abs(p - np.mean(full ** 2)) < tol * np.mean(full ** 2), ("parseval", N)
    assert abs(fft.sum(loc) - full.sum()) < 1e-12 * np.abs(full).sum()
    assert abs(fft.mean(loc) - full.mean()) < 1e-12 * np.abs(full).mean()
    vals = comm.allgather((p, fft.sum(loc)))
    assert all(v == vals[0] for v in vals), "reductions differ between ranks"

    # gather / scatter
    g = fft.gather(loc)
    if comm.rank == 0:
        assert np.array_equal(g, full)
    else:
        assert g is None
    s = fft.scatter(full if comm.rank == 0 else None)
    assert np.array_equal(s, full[rs:re_])

    # wavevectors
    qx, qy, q = fft.wavevectors(L)
    assert q.shape == fft.local_fourier_shape
    assert np.allclose(qx.ravel(), 2 * np.pi / L * np.fft.fftfreq(N, 1.0 / N), rtol=1e-15)
    assert np.allclose(qy.ravel(), 2 * np.pi / L * np.arange(cs, ce), rtol=1e-15)

    # counters: apply x3 (+1 hermitian, N even) + gradient x2 (+2 Nyquist check, N even)
    assert fft.n_apply == (8 if N % 2 == 0 else 5) and fft.pairs == fft.n_apply + min(fft.n_forward, fft.n_backward)
    fft.pairs = 0
    assert fft.pairs == 0 and fft.transforms == 0
    fft.free()


def check_single(comm, N, tol=2e-6):
    """The single-precision twin: float32 arrays, numpy's transforms to float32 rounding (6e-8, times
    the growth of the error with log N and the multiplier's size), its pairs counted in the parent's."""
    fft = SlabFFT(comm, N, planner="estimate", wisdom_file=False)
    one = fft.single()
    assert one is fft.single() and one.single() is one and one.precision == "single"
    assert one.real_array().dtype == np.float32 and one.fourier_array().dtype == np.complex64
    assert (one.row_start, one.col_start, one.local_fourier_shape) == (fft.row_start, fft.col_start,
                                                                       fft.local_fourier_shape)
    rs, re_, cs, ce = fft.row_start, fft.row_stop, fft.col_start, fft.col_stop
    rng = np.random.default_rng(2000 + N)
    full = rng.standard_normal((N, N))
    mult = rng.standard_normal((N, N // 2 + 1)) + 1j * rng.standard_normal((N, N // 2 + 1))
    loc = one.real_array()
    loc[...] = full[rs:re_]
    refa = np.fft.irfft2(np.fft.rfft2(full) * mult, s=(N, N))
    a = one.apply(loc, mult[:, cs:ce].astype(np.complex64))
    assert a.dtype == np.float32
    err = comm.allreduce(float(np.max(np.abs(a - refa[rs:re_]))), op=MPI.MAX)
    assert 0 < err < tol * np.max(np.abs(refa)), ("single apply", N, err)   # float32, not float64
    F = one.forward(loc)
    assert rel(F, np.fft.rfft2(full)[:, cs:ce]) < tol
    assert rel(one.backward(F), full[rs:re_]) < tol
    # the twin's work counts in the parent's counters, as pairs
    assert one.pairs == 2 and fft.pairs == 2 and fft.n_apply == 0
    assert fft.transforms == 4 == fft.single_transforms
    fft.reset_counters()
    assert one.pairs == 0 and fft.transforms == 0
    fft.free()
    one.free()


def check_scale_and_release(comm, N):
    """``apply(..., scale=s)`` is ``apply`` with the multiplier times s (to rounding; s = 1 bit for bit),
    in both precisions; ``release_arrays`` lets go of the caller's arrays that FFTW's plans (and the
    twin's) keep from their last execution."""
    import gc
    import weakref

    fft = SlabFFT(comm, N, planner="estimate", wisdom_file=False)
    one = fft.single()
    rs, re_, cs, ce = fft.row_start, fft.row_stop, fft.col_start, fft.col_stop
    rng = np.random.default_rng(3000 + N)
    full = rng.standard_normal((N, N))
    mult = (rng.standard_normal((N, N // 2 + 1)) + 1j * rng.standard_normal((N, N // 2 + 1)))[:, cs:ce].copy()
    x = fft.real_array()
    x[...] = full[rs:re_]
    ref = fft.apply(x, mult * 0.37)
    assert rel(fft.apply(x, mult, scale=0.37), ref) < 1e-14
    assert np.array_equal(fft.apply(x, mult, scale=1.0), fft.apply(x, mult))
    x32 = x.astype(np.float32)
    assert rel(one.apply(x32, mult.astype(np.complex64), scale=0.37), ref) < 2e-6
    # normalised: the input carries the 1/N^2 (subset.Grid): a power of two for N = 2^k, so the same bits
    plain = fft.apply(x, mult)
    xn = x * fft.norm
    pow2 = N & (N - 1) == 0
    for f, inp in ((fft, xn), (one, xn.astype(np.float32))):
        got = f.apply(inp, mult.astype(f.complex_dtype), normalised=True)
        want = f.apply(inp / f.norm, mult.astype(f.complex_dtype))
        assert np.array_equal(got, want) if pow2 else rel(got, want) < (1e-14 if f is fft else 2e-6)
    across = one.real_array()
    fft.apply_across(one, xn, mult, across, normalised=True)
    assert np.array_equal(across, fft.apply_across(one, x, mult, one.real_array())) if pow2 else \
        rel(across, plain) < 2e-6
    try:
        fft.apply(xn, mult, scale=0.37, normalised=True)
    except ValueError:
        pass
    else:
        raise AssertionError("apply took a scale with normalised input")
    gone = []
    for f, inp in ((fft, x), (one, x32)):
        out = f.apply(inp, mult.astype(f.complex_dtype))
        spec = f.forward(inp)
        gone += [weakref.ref(out), weakref.ref(spec)]
        del out, spec
    gc.collect()
    # the plans hold some of them (which ones depends on the ranks: transposes go through buffers)
    fft.release_arrays()
    gc.collect()
    assert all(r() is None for r in gone), [r() is None for r in gone]
    fft.free()
    one.free()


def check_across(comm, N, tol=2e-6):
    """``apply_across``: the forward transform in one precision and the backward in the twin's.  On a
    smooth field (long waves) and a multiplier that amplifies short waves by up to ~1e3-1e7, the
    float64 forward with a float32 backward rounds like the float32 output it writes (within tol of
    numpy's float64 product, and not exactly it), while rounding the input to float32 first (the float32
    forward) costs more than ten times as much: the amplified rounding noise that float64 forward
    transforms avoid (solver/subset.py, Mixed).  Both count as pairs of the double SlabFFT."""
    fft = SlabFFT(comm, N, planner="estimate", wisdom_file=False)
    one = fft.single()
    rs, re_, cs, ce = fft.row_start, fft.row_stop, fft.col_start, fft.col_stop
    x, y = np.meshgrid(np.arange(N), np.arange(N), indexing="ij")
    full = np.cos(2 * np.pi * x / N) / 3 + 0.3 * np.sin(2 * np.pi * y / N + 0.1)
    kx, ky = np.fft.fftfreq(N, 1.0 / N)[:, None], np.arange(N // 2 + 1)[None, :]
    mult = (1.0 + kx ** 2 + ky ** 2) ** 2 * (1 + 0.5j)
    ref = np.fft.irfft2(np.fft.rfft2(full) * mult, s=(N, N))[rs:re_]
    scale = np.max(np.abs(ref))
    x64, out32 = fft.real_array(), one.real_array()
    x64[...] = full[rs:re_]
    x32, out64 = x64.astype(np.float32), fft.real_array()
    m = np.ascontiguousarray(mult[:, cs:ce])
    assert fft.apply_across(one, x64, m, out32, scale=0.5) is out32 and out32.dtype == np.float32
    err = comm.allreduce(float(np.max(np.abs(out32 - 0.5 * ref))), op=MPI.MAX)
    assert 0 < err < tol * 0.5 * scale, ("across 64 -> 32", N, err / scale)
    one.apply_across(fft, x32, m, out64)
    err_in32 = comm.allreduce(float(np.max(np.abs(out64 - ref))), op=MPI.MAX)
    assert err_in32 > 10 * 2 * err, ("input rounded to float32", N, err_in32 / scale, 2 * err / scale)
    assert fft.pairs == 2 == fft.n_apply and fft.single_transforms == 0 and one.pairs == 0
    for args in ((one, x32, m, out32), (one, x64, m, x64)):      # not this SlabFFT's and its twin's arrays
        try:
            fft.apply_across(*args)
        except ValueError:
            pass
        else:
            raise AssertionError("apply_across accepted wrong arrays")
    fft.free()
    one.free()


def check_all(comm):
    for N in SIZES:
        if comm.size <= N // 2:
            check_one(comm, N)
            check_single(comm, N)
            check_scale_and_release(comm, N)
            check_across(comm, N)


if __name__ == "__main__":
    comm = MPI.COMM_WORLD
    try:
        check_all(comm)
    except BaseException:
        import traceback

        traceback.print_exc()
        sys.stderr.flush()
        comm.Abort(1)
    if comm.rank == 0:
        print("PFFT_OK", comm.size)
