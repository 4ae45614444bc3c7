"""Benchmark of the distributed FFT (vecontact.core.pfft.SlabFFT).

Usage (from the repository root):  python benchmarks/fft.py [--sizes 1024,2048,4096] [--planner measure]

Starts its own MPI runs (mpiexec -n 1 and -n 2 of this file with --worker) and times
forward+backward pairs of SlabFFT (median over repeats; per repeat the slowest rank counts) next to a
raw single-process pyfftw rfft2/irfft2 pair (pyfftw.builders, same planner flag, threads=1).
A separate fresh 2-rank run does one forward+backward pair at the largest N and reports the peak RSS
per rank (resource.getrusage ru_maxrss).  Prints a table; the LAST line is one JSON object:
{"overhead": t_1rank / t_raw at N=2048, "speedup": t_1rank / t_2rank at N=2048, ...}.

``--breakdown N`` (issue #15: is the 2-rank pair slow in the transposes or in the local FFTs?) instead
times, at one N, the stages of a 2-rank pair one by one (a barrier before each, the slowest rank
counts, minimum over repeats): the row r2c, the Alltoallw of subarray datatypes, the column FFT, and
back; next to them the same transpose done as numpy packing into contiguous blocks + ``Alltoall``; and,
single-process, the raw pyfftw pair on 1 and on 2 threads.  Last line: JSON of every stage (ms).

``--precisions N`` times, at one N on 1 and on 2 ranks, the pairs a solve can run: float64, float32,
and the two mixed ones of ``SlabFFT.apply_across`` (float64 forward + float32 backward, float32 forward
+ float64 backward; SolverSettings.mixed_pairs) and the float64 and float32 pairs of an input that
carries the 1/N^2 already (``apply(..., normalised=True)``: no pass over the output; subset.Grid), in
turn for three rounds (the slowest rank counts,
minimum over repeats and rounds), and prints each as a ratio to the float64 pair of the same run.
Last line: JSON of the times (ms) and ratios.
"""
import argparse
import json
import os
import resource
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)


def _median(xs):
    xs = sorted(xs)
    n = len(xs)
    return xs[n // 2] if n % 2 else 0.5 * (xs[n // 2 - 1] + xs[n // 2])


def _repeats(t_one, budget):
    return int(max(5, min(200, budget / max(t_one, 1e-6))))


def worker(args):
    import numpy as np
    from mpi4py import MPI
    import pyfftw
    import pyfftw.builders as builders
    from vecontact.core.pfft import SlabFFT

    comm = MPI.COMM_WORLD
    flag = {"estimate": "FFTW_ESTIMATE", "measure": "FFTW_MEASURE", "patient": "FFTW_PATIENT"}[args.planner]
    out = {"size": comm.size, "results": []}
    if args.precisions:
        out.update(_precisions(comm, args.precisions, args.planner, args.budget))
        if comm.rank == 0:
            print("RESULT " + json.dumps(out), flush=True)
        return
    if args.breakdown:
        out.update(_breakdown(comm, args.breakdown, args.planner, flag, args.budget))
        if comm.rank == 0:
            print("RESULT " + json.dumps(out), flush=True)
        return
    if args.mem:
        N = args.mem
        t0 = time.perf_counter()
        fft = SlabFFT(comm, N, threads=1, planner=args.planner)
        tplan = time.perf_counter() - t0
        x = fft.real_array()
        x[...] = np.random.default_rng(comm.rank).standard_normal(x.shape)
        F = fft.fourier_array()
        y = fft.real_array()
        fft.forward(x, F)
        fft.backward(F, y)
        rss_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9  # kB on Linux
        rss = comm.gather(rss_gb, root=0)
        if comm.rank == 0:
            out.update(mem_N=N, rss_gb=rss, plan_s=tplan)
            print("RESULT " + json.dumps(out), flush=True)
        return
    for N in args.sizes:
        rec = {"N": N}
        t0 = time.perf_counter()
        fft = SlabFFT(comm, N, threads=1, planner=args.planner)
        rec["plan_s"] = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
        x = fft.real_array()
        x[...] = np.random.default_rng(comm.rank).standard_normal(x.shape)
        F = fft.fourier_array()
        y = fft.real_array()
        raw = None
        if args.raw:  # single process only: raw pyfftw pair, interleaved with the SlabFFT pair
            a = pyfftw.empty_aligned((N, N), dtype="float64")
            a[...] = x
            fwd = builders.rfft2(a, planner_effort=flag, threads=1)
            bwd = builders.irfft2(fwd.output_array, s=(N, N), planner_effort=flag, threads=1)
            a[...] = x

            def raw():
                bwd(fwd(a))

        comm.Barrier()
        t0 = time.perf_counter()
        fft.forward(x, F)
        fft.backward(F, y)
        t1 = comm.allreduce(time.perf_counter() - t0, op=MPI.MAX)
        nrep = _repeats(t1 * (2 if raw else 1), args.budget)
        ts, tr = [], []
        for _ in range(nrep):
            if raw:
                t0 = time.perf_counter()
                raw()
                tr.append(time.perf_counter() - t0)
            comm.Barrier()
            t0 = time.perf_counter()
            fft.forward(x, F)
            fft.backward(F, y)
            ts.append(time.perf_counter() - t0)
        ts = np.array(ts)
        tmax = np.empty_like(ts)
        comm.Allreduce(ts, tmax, op=MPI.MAX)
        rec["slab"] = _median(list(tmax))
        rec["slab_min"] = float(tmax.min())
        if raw:
            rec["raw"] = _median(tr)
            rec["raw_min"] = min(tr)
        rec["repeats"] = nrep
        err = comm.allreduce(float(np.abs(y - x).max()), op=MPI.MAX)
        rec["roundtrip_err"] = err
        out["results"].append(rec)
        fft.free()
        del fft, x, F, y
    if comm.rank == 0:
        print("RESULT " + json.dumps(out), flush=True)


def _stage_min(comm, fn, reps):
    """Minimum over ``reps`` of the slowest rank's time of fn() (s), a barrier before each."""
    import numpy as np
    from mpi4py import MPI
    ts = np.empty(reps)
    for i in range(reps):
        comm.Barrier()
        t0 = time.perf_counter()
        fn()
        ts[i] = time.perf_counter() - t0
    tmax = np.empty_like(ts)
    comm.Allreduce(ts, tmax, op=MPI.MAX)
    return float(tmax.min())


def _breakdown(comm, N, planner, flag, budget):
    """Stage times (ms) of a SlabFFT pair on this communicator (2 ranks), or of the raw pyfftw pair on 1
    and 2 threads (1 rank)."""
    import numpy as np
    import pyfftw
    import pyfftw.builders as builders
    from mpi4py import MPI
    from vecontact.core.pfft import SlabFFT, _run
    if comm.size == 1:
        a = pyfftw.empty_aligned((N, N), dtype="float64")
        a[...] = np.random.default_rng(0).standard_normal((N, N))
        res = {}
        for threads in (1, 2):
            fwd = builders.rfft2(a, planner_effort=flag, threads=threads)
            bwd = builders.irfft2(fwd.output_array, s=(N, N), planner_effort=flag, threads=threads)
            t1 = _stage_min(comm, lambda: bwd(fwd(a)), 1)
            res[f"raw_pair_{threads}thread_ms"] = 1e3 * _stage_min(comm, lambda: bwd(fwd(a)), _repeats(t1, budget))
        return res
    fft = SlabFFT(comm, N, threads=1, planner=planner)
    x = fft.real_array()
    x[...] = np.random.default_rng(comm.rank).standard_normal(x.shape)
    mult = fft.fourier_array()
    mult[...] = 1.0
    y = fft.real_array()
    A, B = fft._A, fft._B
    # the transpose by hand: my columns of every rank's block packed contiguous, Alltoall, unpacked
    cols = fft._cols
    send = np.empty(A.size, dtype=A.dtype)
    recv = np.empty(B.size, dtype=B.dtype)
    counts = [fft.nrows * (c1 - c0) for c0, c1 in cols]
    rows = comm.allgather(fft.nrows)
    rcounts = [r * fft.ncols for r in rows]

    def packed():
        off = 0
        for c0, c1 in cols:
            n = fft.nrows * (c1 - c0)
            send[off:off + n].reshape(fft.nrows, c1 - c0)[...] = A[:, c0:c1]
            off += n
        comm.Alltoallv([send, (counts, np.cumsum([0] + counts[:-1]))],
                       [recv, (rcounts, np.cumsum([0] + rcounts[:-1]))])
        off = 0
        r0 = 0
        for r in rows:
            B[r0:r0 + r, :] = recv[off:off + r * fft.ncols].reshape(r, fft.ncols)
            off += r * fft.ncols
            r0 += r

    stages = {
        "pair": lambda: fft.apply(x, mult, y),
        "r2c_rows": lambda: _run(fft._p_r2c, x, A),
        "transpose_alltoallw": fft._a2b,
        "fft_columns": fft._p_xf_ip.execute,
        "ifft_columns": fft._p_xb_ip.execute,
        "transpose_back_alltoallw": fft._b2a,
        "c2r_rows": lambda: _run(fft._p_c2r, A, y),
        "transpose_packed_alltoallv": packed,
    }
    stages["r2c_rows"]()
    fft._a2b()
    want = B.copy()
    packed()
    same = comm.allreduce(bool(np.array_equal(B, want)), op=MPI.LAND)
    if not same:
        raise RuntimeError("the packed transpose does not reproduce the Alltoallw one")
    t1 = _stage_min(comm, stages["pair"], 1)
    reps = _repeats(t1, budget)
    return {f"{k}_ms": 1e3 * _stage_min(comm, fn, reps) for k, fn in stages.items()}


PRECISIONS = ("double", "single", "f64_forward_f32_backward", "f32_forward_f64_backward", "double_normalised",
              "single_normalised")


def _precisions(comm, N, planner, budget):
    """Minimum times (ms) of the pairs of PRECISIONS on this communicator, in turn for three rounds."""
    import numpy as np
    from vecontact.core.pfft import SlabFFT
    fft = SlabFFT(comm, N, threads=1, planner=planner)
    one = fft.single()
    rng = np.random.default_rng(comm.rank)
    x64, y64 = fft.real_array(), fft.real_array()
    x64[...] = rng.standard_normal(x64.shape)
    x32, y32 = one.real_array(), one.real_array()
    x32[...] = x64
    m64 = 1.0 + rng.random(fft.local_fourier_shape) + 0.5j
    m32 = m64.astype(np.complex64)
    pairs = dict(zip(PRECISIONS, (lambda: fft.apply(x64, m64, y64), lambda: one.apply(x32, m32, y32),
                                  lambda: fft.apply_across(one, x64, m64, y32),
                                  lambda: one.apply_across(fft, x32, m64, y64),
                                  # the same arrays without the pass over the output (their values do not
                                  # change the time; arrays allocated later placed differently did)
                                  lambda: fft.apply(x64, m64, y64, normalised=True),
                                  lambda: one.apply(x32, m32, y32, normalised=True))))
    reps = _repeats(_stage_min(comm, pairs["double"], 1), budget / len(pairs))
    best = {k: float("inf") for k in pairs}
    for _ in range(3):
        for k, fn in pairs.items():
            best[k] = min(best[k], 1e3 * _stage_min(comm, fn, reps))
    return {f"{k}_ms": v for k, v in best.items()}


def launch(n, extra):
    sys.path.insert(0, os.path.join(ROOT, "tests"))
    from mpi_util import run_mpi  # noqa: E402

    env = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    proc = run_mpi(n, [os.path.abspath(__file__), "--worker"] + extra, timeout=3600, env=env)
    for line in proc.stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line[7:])
    raise RuntimeError(proc.stdout + proc.stderr)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", default="1024,2048,4096")
    ap.add_argument("--planner", default="measure", choices=["estimate", "measure", "patient"])
    ap.add_argument("--budget", type=float, default=3.0, help="seconds of timing per case")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--raw", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--mem", type=int, default=0, help=argparse.SUPPRESS)
    ap.add_argument("--precisions", type=int, default=0, metavar="N",
                    help="float64, float32 and mixed pairs at N on 1 and 2 ranks (see above)")
    ap.add_argument("--breakdown", type=int, default=0, metavar="N",
                    help="stage times of a 2-rank pair at N (see above) instead of the size table")
    args = ap.parse_args()
    args.sizes = [int(s) for s in args.sizes.split(",") if s]
    if args.worker:
        try:
            return worker(args)
        except BaseException:
            import traceback
            from mpi4py import MPI
            traceback.print_exc()
            sys.stderr.flush()
            MPI.COMM_WORLD.Abort(1)

    if args.precisions:
        extra = ["--precisions", str(args.precisions), "--planner", args.planner, "--budget", str(args.budget)]
        res = {"N": args.precisions, "planner": args.planner}
        print(f"N={args.precisions}, planner={args.planner}: minimum pair times (ms) and ratio to the float64 pair")
        for n in (1, 2):
            r = launch(n, extra)
            for k in PRECISIONS:
                t, ratio = r[k + "_ms"], r[k + "_ms"] / r["double_ms"]
                print(f"  {n} rank{'s' if n > 1 else ' '} {k:26s} {t:10.2f} {ratio:7.3f}")
                res[f"{k}_ms_{n}rank"], res[f"{k}_ratio_{n}rank"] = round(t, 3), round(ratio, 4)
        print(json.dumps(res))
        return
    if args.breakdown:
        extra = ["--breakdown", str(args.breakdown), "--planner", args.planner, "--budget", str(args.budget)]
        one, two = launch(1, extra), launch(2, extra)
        res = {k: round(v, 3) for k, v in {**one, **two}.items() if k.endswith("_ms")}
        print(f"N={args.breakdown}, planner={args.planner}: minimum stage times (ms), 2 ranks unless marked")
        for k, v in res.items():
            print(f"  {k[:-3]:28s} {v:10.2f}")
        two_ranks = res["pair_ms"]
        res.update(N=args.breakdown, speedup_2ranks=round(res["raw_pair_1thread_ms"] / two_ranks, 3),
                   speedup_2threads=round(res["raw_pair_1thread_ms"] / res["raw_pair_2thread_ms"], 3),
                   transpose_share=round((res["transpose_alltoallw_ms"] + res["transpose_back_alltoallw_ms"])
                                         / two_ranks, 3))
        print(json.dumps(res))
        return
    common = ["--sizes", ",".join(map(str, args.sizes)), "--planner", args.planner, "--budget", str(args.budget)]
    r1 = launch(1, common + ["--raw"])
    r2 = launch(2, common)
    Nmem = max(args.sizes)
    m2 = launch(2, ["--mem", str(Nmem), "--planner", args.planner])
    m1 = launch(1, ["--mem", str(Nmem), "--planner", args.planner])

    by1 = {r["N"]: r for r in r1["results"]}
    by2 = {r["N"]: r for r in r2["results"]}
    print(f"SlabFFT forward+backward pair, planner={args.planner}, threads=1 per rank, median times")
    hdr = f"{'N':>6} {'raw pyfftw [ms]':>16} {'1 rank [ms]':>12} {'2 ranks [ms]':>13} {'overhead':>9} {'speedup':>8} {'reps(1/2)':>10}"
    print(hdr)
    print("-" * len(hdr))
    for N in args.sizes:
        a, b = by1[N], by2[N]
        print(f"{N:>6} {a['raw'] * 1e3:>16.2f} {a['slab'] * 1e3:>12.2f} {b['slab'] * 1e3:>13.2f} "
              f"{a['slab'] / a['raw']:>9.3f} {a['slab'] / b['slab']:>8.3f} {a['repeats']:>5}/{b['repeats']:<4}")
    print(f"peak RSS per rank, one pair at N={Nmem}: 2 ranks {', '.join(f'{g:.3f}' for g in m2['rss_gb'])} GB; "
          f"1 rank {m1['rss_gb'][0]:.3f} GB")
    Nref = 2048 if 2048 in by1 else args.sizes[0]
    res = {
        "overhead": round(by1[Nref]["slab"] / by1[Nref]["raw"], 4),
        "speedup": round(by1[Nref]["slab"] / by2[Nref]["slab"], 4),
        "N_ref": Nref,
        "planner": args.planner,
    }
    for N in args.sizes:
        res[f"t_raw_ms_{N}"] = round(by1[N]["raw"] * 1e3, 3)
        res[f"t_1rank_ms_{N}"] = round(by1[N]["slab"] * 1e3, 3)
        res[f"t_2rank_ms_{N}"] = round(by2[N]["slab"] * 1e3, 3)
        res[f"overhead_{N}"] = round(by1[N]["slab"] / by1[N]["raw"], 4)
        res[f"speedup_{N}"] = round(by1[N]["slab"] / by2[N]["slab"], 4)
    res[f"mem_gb_{Nmem}_2ranks"] = round(max(m2["rss_gb"]), 4)
    res[f"mem_gb_{Nmem}_1rank"] = round(m1["rss_gb"][0], 4)
    print(json.dumps(res))


if __name__ == "__main__":
    main()
