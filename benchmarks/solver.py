"""Benchmark of the exact contact solver (vecontact.solver.solve_contact).

Usage (from the repository root):
    python benchmarks/solver.py [--max-n 4096] [--quick] [--ranks 2] [--areas 0.01,0.05,0.3]
                                [--velocities 0.01,10] [--no-pk] [--out results.jsonl]
                                [--areas-4096 0.05] [--pk-max-n 2048] [--blas LIBDIR]
                                [--repeat 3] [--no-oracle]

Starts its own MPI runs (``mpiexec -n RANKS python benchmarks/solver.py --worker N ...``), one per grid
size, on the paper's surfaces (jobs/paper.yaml's, benchmarks/paper_case.py; docs/conventions.md §2: q0 =
2.5e5 1/m, qr = 4 q0, H = 0.8, C0 = 1.0616e-28 m^4, q1 = N/16 q0, i.e. N = 512, 1024, 2048, 4096 for q1
= 32..256 q0, seed 1) with the reference Havriliak-Negami compound at v = 0.01 and 10 m/s, nominal
pressures aimed at A/A0 ~ 1 %, 5 %, 30 % (Persson's theory, corrected by one cheap coarse-grid solve on
the N/4 grid, which holds all the roughness; the A/A0 actually reached is reported).  Next to every
viscoelastic solve the worker runs Polonsky-Keer on the elastic problem (E = E0) on the same surface,
aimed at the same A/A0, and times the raw distributed FFT pair (SlabFFT.apply) of the same grid and rank
count.

Output: a table, then as LAST line one JSON object:
  pk_ratio_max         max over N >= 1024 of (our FFT pairs) / (PK FFT pairs), same N and target A/A0
  pk_iter_ratio_max    the same against PK *iterations* (PK's nominal "one pair per iteration")
  pairs_growth         max over (v, A/A0) of pairs(N_max) / pairs(512)
  time_per_pair_ratio  max over N >= 1024 of solver seconds / (fft_pairs x raw pair seconds); the raw
                       pair is the minimum of --fft-repeats timings (the median is printed too); every
                       FFTW plan a solve uses (coarse grids, float32 twins) is made before any clock,
                       as the fine grid's (``t_plan`` of the fft record)
                       = (solver seconds / seconds inside SlabFFT.apply) x (seconds inside apply /
                       (fft_pairs x raw pair)): the two factors' maxima over N >= 1024 are
                       solve_over_pairs_max (the work outside the pairs) and pair_in_solve_ratio_max (a
                       pair inside the solve against the raw pair; coarse-grid pairs at their own cost)
  time_per_pair_ratio_paced  the same with each case's own raw pair: the fastest of --case-pairs timed
                       right after the case's solves, in the same process (the machine's pace drifts
                       between the start of a run and a case minutes later by more than the target's
                       margin; the farm's pace probe does the same: docs/farm.md)
  seconds_4096         wall time of the 4096^2, A/A0 ~ 5 % solve on 2 ranks (max over v)
  overhead_max         max over the cases of (the solve's FFT pairs, fine-grid equivalents, coarse grids
                       included) / (the oracle solve's FFT pairs): the oracle solve (issue #15) is one
                       Newton step on the case's final contact set from a uniform pressure, its inner
                       FGMRES run to --oracle-rtol (contactset.oracle_solve) without a restart while its
                       basis fits --oracle-memory GB a rank (a restart adds iterations and would flatter
                       the ratio; --oracle-krylov gmres: right-preconditioned GMRES, the same iterations
                       from half the basis, for the large sets of 4096^2); only the cases whose oracle
                       converged count, ``overhead_bounds`` lists the others' upper bounds (their oracle
                       stopped at --oracle-max-it), ``overhead_restarted`` the cases whose oracle
                       restarted all the same (lower bounds, counted in the max), and ``--no-oracle``
                       skips the oracle (n/a, null)
  overhead_matched_max the same against the oracle carried to the solve's own accuracy: from p^ = 1 its
                       rtol 1e-8 leaves a measure of 4e-5-5e-4 where the solve meets --tol, so one
                       refinement step on the same set follows, stopped at the first iterate that meets
                       the solve's test (contactset.oracle_solve's ``tol``); only the cases where it met
                       it count (``--no-oracle-matched``: not run).  Not #15's target, which is
                       overhead_max: context for it (benchmarks/RESULTS.md)
  all_converged        every vecontact and PK solve converged (the oracle is not a solve of the case)
plus the medians and the targets.  With ``--repeat K`` every viscoelastic solve runs K times and its
seconds are the fastest run's, as the raw pair's are the fastest of --fft-repeats (this machine's
run-to-run noise is of the order of the time-per-pair target's margin); the K runs must count the same
FFT pairs, else the worker stops.  With ``--blas LIBDIR`` every N runs twice, with the BLAS PETSc links
and with LIBDIR's libblas.so.3 first on LD_LIBRARY_PATH; the headline figures are the first run's, and
``blas`` gives the other's time_per_pair_ratio, the libraries each run actually mapped, and per case its
seconds, pairs and seconds per pair over the reference's.  ``--quick`` runs only A/A0 ~ 5 % and v = 0.01
and 10 without PK at 4096.
"""
import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import threading
import time
from statistics import median

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)




# ------------------------------------------------------------------------------------------ worker
def worker(args):
    sys.path.insert(0, ROOT)
    from mpi4py import MPI
    from scipy.special import erfinv
    import paper_case
    from vecontact.core.pfft import SlabFFT, apply_seconds
    from vecontact.physics.theory import persson
    from vecontact.solver import SolverSettings, solve_contact
    from vecontact.solver.contactset import oracle_solve
    from vecontact.solver.operator import ContactOperator
    from vecontact.solver.options import parse
    from vecontact.solver.warmstart import coarse_fft, coarse_levels, fourier_transfer

    comm = MPI.COMM_WORLD
    N = args.n
    L = paper_case.period()
    spec = paper_case.spectrum(N)
    hn = paper_case.compound()
    el = paper_case.elastic()
    t0 = time.perf_counter()
    fft = SlabFFT(comm, N, planner=args.planner)
    h = paper_case.surface(fft, args.seed)
    t_setup = time.perf_counter() - t0
    # FFTW plans every SlabFFT a solve at N uses (the coarse grids', the float32 twins) before the clock,
    # as the fine grid's above: else the first case's seconds carry them (0.2-0.4 s at 1024^2, a tenth of
    # that solve; RESULTS.md)
    t0 = time.perf_counter()
    cfg = SolverSettings().with_options(parse(args.petsc))    # the solves' own settings (their -vc_ options)
    for n in coarse_levels(N, comm.size, cfg.coarse_min_n, cfg.coarse_levels):
        coarse_fft(fft, n).single()
    fft.single()
    t_plan = time.perf_counter() - t0

    # raw distributed FFT pair; the minimum: its cost without the machine's noise (medians of 7 swung
    # 32-62 ms at 2048^2)
    t_pair, t_pair_median = fft.time_pair(args.fft_repeats)

    # coarse copy of the surface (N/4 holds all the roughness) for the pressure calibration
    nc = max(N // 4, 64)
    fc = coarse_fft(fft, nc)
    hc = fc.backward(fourier_transfer(fft, fft.forward(h), fc))

    def emit(rec):
        if comm.rank == 0:
            print("RESULT " + json.dumps(rec), flush=True)

    def calibrate(mod, v, area):
        th = persson(spec, mod, [v], [1.0])
        G1 = float(th.G_q[0, 0, -1])
        s = 2.0 * math.sqrt(G1)        # theory: A = erf(sigma / s)
        sig = s * erfinv(area)
        for _ in range(args.calib_steps):
            rc = solve_contact(fc, L, hc, mod, v, sig, tolerance=1e-4, store=())
            if not (0 < rc.area < 1):
                break
            s = sig / erfinv(rc.area)
            sig = s * erfinv(area)
        return sig

    emit(dict(kind="fft", N=N, ranks=comm.size, t_pair=t_pair, t_pair_median=t_pair_median, t_setup=t_setup,
              t_plan=t_plan))
    pk_done = {}
    for area in args.areas:
        for v in args.velocities:
            sig = calibrate(hn, v, area)
            runs = []                     # (seconds, seconds inside SlabFFT.apply, FFT pairs) per repeat
            for _ in range(args.repeat):
                s0 = apply_seconds()
                r = solve_contact(fft, L, h, hn, v, sig, tolerance=args.tol, store=("pressure",),
                                  petsc_options=args.petsc)
                runs.append((r.seconds, comm.allreduce(apply_seconds() - s0, op=MPI.MAX), r.fft_pairs))
            # the raw pair again, right after the case: the machine's pace of the solve (it drifts by more
            # than the target's margin between the start of a run and a case minutes later)
            t_pair_case = fft.time_pair(args.case_pairs)[0] if args.case_pairs else None
            if len({p for _, _, p in runs}) != 1:
                raise SystemExit(f"N={N} v={v} target={area}: the repeats counted different FFT pairs "
                                 f"{[p for _, _, p in runs]}: the solve is not deterministic")
            # the fastest repeat: the solve's cost without the machine's noise, as the raw pair's minimum
            seconds, pair_seconds, _ = min(runs)
            orc = (oracle_solve(ContactOperator(fft, L, hn, v, sig, h), r.pressure > 0, args.oracle_rtol,
                                args.oracle_max_it, SolverSettings(), memory=args.oracle_memory * 1e9,
                                krylov=args.oracle_krylov, tol=args.tol if args.oracle_matched else None)
                   if args.oracle else dict(iterations=None, pairs=None, converged=None, restart=None))
            matched = orc.get("matched") or dict(iterations=None, pairs=None, converged=None, measure=None)
            emit(dict(kind="snes", N=N, ranks=comm.size, v=v, target=area, sigma0=sig, area=r.area,
                      mu=r.mu, mu_geometric=r.mu_geometric, converged=r.converged, residual=r.residual,
                      iterations=r.iterations, linear_iterations=r.linear_iterations,
                      pairs=r.fft_pairs, by_level=r.fft_pairs_by_level, seconds=seconds,
                      seconds_median=median(t for t, _, _ in runs), repeats=len(runs),
                      pair_seconds=pair_seconds,
                      t_pair=t_pair, t_pair_case=t_pair_case, levels=r.diagnostics["levels"], reason=r.reason,
                      lin_history=r.diagnostics["linear_history"],
                      set_changes=r.diagnostics["active_set_changes"],
                      history=r.diagnostics["history"],
                      measure_checks=r.diagnostics["measure_checks"],
                      oracle_iterations=orc["iterations"], oracle_pairs=orc["pairs"],
                      oracle_converged=orc["converged"], oracle_restart=orc["restart"],
                      oracle_krylov=args.oracle_krylov if args.oracle else None,
                      overhead=r.fft_pairs / orc["pairs"] if orc["pairs"] else None,
                      oracle_matched_iterations=matched["iterations"], oracle_matched_pairs=matched["pairs"],
                      oracle_matched_converged=matched["converged"], oracle_matched_measure=matched["measure"],
                      oracle_measure=matched.get("plain_measure"),
                      overhead_matched=r.fft_pairs / matched["pairs"] if matched["pairs"] else None,
                      blas_lib=_loaded_blas()))   # after the solve: PETSc (and its libblas) is loaded
            del r
        if args.pk and not (args.quick and N >= 4096) and area not in pk_done:
            sig = calibrate(el, 0.0, area)
            r = solve_contact(fft, L, h, el, 0.0, sig, tolerance=args.tol, method="pk", store=())
            pk_done[area] = True
            emit(dict(kind="pk", N=N, ranks=comm.size, v=0.0, target=area, sigma0=sig, area=r.area,
                      converged=r.converged, residual=r.residual, iterations=r.iterations,
                      pairs=r.fft_pairs, seconds=r.seconds, t_pair=t_pair, reason=r.reason))


def _loaded_blas():
    """Path of the BLAS library mapped into this process (proof of what --blas actually loaded)."""
    with open("/proc/self/maps") as fh:
        libs = {line.split()[-1] for line in fh if "blas" in line.rsplit("/", 1)[-1]}
    return ",".join(sorted(libs)) or None


# -------------------------------------------------------------------------------------------- main
def _mpiexec():
    import shutil
    exe = shutil.which("mpiexec", path=os.path.dirname(sys.executable) + os.pathsep + os.environ.get("PATH", ""))
    if exe is None:
        raise SystemExit("mpiexec not found next to the Python interpreter or on PATH")
    return exe


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--n", type=int, default=512, help=argparse.SUPPRESS)
    ap.add_argument("--max-n", type=int, default=4096)
    ap.add_argument("--min-n", type=int, default=512)
    ap.add_argument("--sizes", type=str, default=None, help="comma list of N (overrides min/max)")
    ap.add_argument("--ranks", type=int, default=2, help="ranks for every N (4096 always uses 2)")
    ap.add_argument("--areas", type=str, default="0.01,0.05,0.3")
    ap.add_argument("--velocities", type=str, default="0.01,10")
    ap.add_argument("--quick", action="store_true", help="A/A0 ~ 5 %% only, no PK at 4096")
    ap.add_argument("--no-pk", dest="pk", action="store_false")
    ap.add_argument("--areas-4096", type=str, default=None,
                    help="comma list of A/A0 targets for N >= 4096 only (default: --areas)")
    ap.add_argument("--pk-max-n", type=int, default=1 << 30, help="no Polonsky-Keer above this N")
    ap.add_argument("--tol", type=float, default=1e-8)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--planner", default="measure")
    ap.add_argument("--fft-repeats", type=int, default=15)
    ap.add_argument("--case-pairs", type=int, default=5,
                    help="raw pairs timed right after each case (its paced ratio: the fastest); 0: none")
    ap.add_argument("--calib-steps", type=int, default=2)
    ap.add_argument("--oracle-rtol", type=float, default=1e-8, help="rtol of the oracle solve")
    ap.add_argument("--oracle-max-it", type=int, default=2000, help="iteration cap of the oracle solve")
    ap.add_argument("--oracle-memory", type=float, default=6.0,
                    help="GB a rank for the oracle's FGMRES basis: it restarts only beyond it")
    ap.add_argument("--oracle-krylov", choices=("fgmres", "gmres"), default="fgmres",
                    help="the oracle's Krylov method: gmres (right-preconditioned) takes FGMRES's iterations "
                         "from half its basis, one pair more: unrestarted on larger sets (4096^2)")
    ap.add_argument("--no-oracle-matched", dest="oracle_matched", action="store_false",
                    help="skip the oracle's refinement to the solve's accuracy (overhead_matched: null)")
    ap.add_argument("--no-oracle", dest="oracle", action="store_false",
                    help="skip the oracle solve (overhead not measured: printed as n/a, null in the JSON)")
    ap.add_argument("--repeat", type=int, default=1,
                    help="run every viscoelastic solve this many times; its seconds are the fastest run's "
                         "(the median is printed too); the runs must count the same FFT pairs")
    ap.add_argument("--petsc", type=str, default="",
                    help="PETSc / -vc_ options of every viscoelastic solve, e.g. '-vc_lin_rtol 0.3'")
    ap.add_argument("--out", default=None, help="also append the raw RESULT records (JSON lines) here")
    ap.add_argument("--timeout", type=float, default=7200.0, help="per MPI run (s)")
    ap.add_argument("--blas", default=None, metavar="LIBDIR",
                    help="run every N twice, with the BLAS PETSc links (reference) and with the libblas.so.3 "
                         "in LIBDIR first on LD_LIBRARY_PATH (e.g. Debian's OpenBLAS), and compare")
    args = ap.parse_args()
    args.areas = [float(x) for x in args.areas.split(",")]
    args.velocities = [float(x) for x in args.velocities.split(",")]
    if args.quick:
        args.areas = [0.05]
    if args.repeat < 1:
        ap.error("--repeat: must be >= 1")
    if args.worker:
        return worker(args)

    if args.sizes:
        sizes = [int(x) for x in args.sizes.split(",")]
    else:
        sizes = [n for n in (512, 1024, 2048, 4096) if args.min_n <= n <= args.max_n]
    records, failed = [], []
    env = dict(os.environ)
    env["PYTHONPATH"] = ROOT + os.pathsep + env.get("PYTHONPATH", "")
    env.setdefault("OMP_NUM_THREADS", "1")
    variants = [("reference", None), (args.blas, args.blas)] if args.blas else [(None, None)]
    for N in sizes:
        ranks = 2 if N >= 4096 else args.ranks
        cmd = [_mpiexec(), "-n", str(ranks), sys.executable, os.path.abspath(__file__), "--worker",
               "--n", str(N),
               "--areas", args.areas_4096 if (N >= 4096 and args.areas_4096) else ",".join(map(str, args.areas)),
               "--velocities", ",".join(map(str, args.velocities)), "--tol", str(args.tol),
               "--seed", str(args.seed), "--planner", args.planner,
               "--fft-repeats", str(args.fft_repeats), "--case-pairs", str(args.case_pairs),
               "--calib-steps", str(args.calib_steps),
               "--oracle-rtol", str(args.oracle_rtol), "--oracle-max-it", str(args.oracle_max_it),
               "--oracle-memory", str(args.oracle_memory), "--oracle-krylov", args.oracle_krylov,
               "--repeat", str(args.repeat), "--petsc=" + args.petsc]
        if args.quick:
            cmd.append("--quick")
        if not args.oracle:
            cmd.append("--no-oracle")
        if not args.oracle_matched:
            cmd.append("--no-oracle-matched")
        if not args.pk or N > args.pk_max_n:
            cmd.append("--no-pk")
        for label, libdir in variants:
            venv = dict(env)
            if libdir:
                venv["LD_LIBRARY_PATH"] = libdir + os.pathsep + env.get("LD_LIBRARY_PATH", "")
            if not _run_worker(cmd, venv, N, ranks, label, args, records):
                failed.append(N)
    summary = summarise(records)
    summary["workers_failed"] = failed
    summary["all_converged"] = summary["all_converged"] and not failed
    print(json.dumps(summary))
    if failed:          # a crashed or timed-out size is not a measurement
        raise SystemExit(1)


def _run_worker(cmd, env, N, ranks, label, args, records):
    """One MPI run of the worker; its RESULT records (tagged with the BLAS label) go to ``records``."""
    tag = f" [BLAS {label}]" if label else ""
    print(f"# N={N} on {ranks} ranks{tag} ...", flush=True)
    t = time.time()
    # each case's row as soon as the worker prints it (a 2048^2 run takes many minutes);
    # stderr to a file so that a full pipe cannot stall the worker
    with tempfile.TemporaryFile("w+") as errf:
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=errf, text=True, env=env, cwd=ROOT)
        timer = threading.Timer(args.timeout, proc.kill)
        timer.start()
        for line in proc.stdout:
            if line.startswith("RESULT "):
                rec = json.loads(line[7:])
                rec["blas"] = label
                records.append(rec)
                if args.out:
                    with open(args.out, "a") as fh:
                        fh.write(json.dumps(rec) + "\n")
                _print_row(rec)
        proc.wait()
        if not timer.is_alive():
            print(f"# N={N}: TIMEOUT after {args.timeout:.0f} s", flush=True)
        timer.cancel()
        errf.seek(0)
        err = errf.read()
    print(f"# N={N}{tag} done in {time.time() - t:.0f} s", flush=True)
    if proc.returncode != 0:
        print(f"# N={N}: worker failed ({proc.returncode}):\n{err[-3000:]}", flush=True)
        return False
    return True


def _per_pair(r, seconds, t_pair):
    """``seconds`` / (the case's FFT pairs x ``t_pair``): time per pair in units of a raw pair."""
    return seconds / (max(r["pairs"], 1e-9) * t_pair)


def _print_row(r):
    if r["kind"] == "fft":
        print(f"{'fft':5s} N={r['N']:5d} ranks={r['ranks']} raw pair {r['t_pair'] * 1e3:8.2f} ms (min; median "
              f"{r.get('t_pair_median', float('nan')) * 1e3:.2f} ms); setup {r['t_setup']:.2f} s, plans of the "
              f"coarse grids and float32 twins {r.get('t_plan', float('nan')):.2f} s (not timed in the solves)",
              flush=True)
        return
    tpp = _per_pair(r, r["seconds"], r["t_pair"])
    extra = ""
    if r["kind"] == "snes":
        lv = " ".join(f"{k}:{v:.0f}" for k, v in r["by_level"].items())
        extra = (f" lin={r['linear_iterations']:4d} mu={r['mu']:.6f} mu_geo={r['mu_geometric']:.4f} [{lv}]"
                 + _oracle_text(r) +
                 f" in_pairs={r['pair_seconds'] / r['seconds']:.3f}"
                 f" pair_in_solve/raw={_per_pair(r, r['pair_seconds'], r['t_pair']):.2f}")
        if r.get("t_pair_case"):
            extra += (f" paced={_per_pair(r, r['seconds'], r['t_pair_case']):.2f}"
                      f" (pair after {r['t_pair_case'] * 1e3:.2f} ms)")
        if r.get("repeats", 1) > 1:
            extra += f" fastest of {r['repeats']} (median t={r['seconds_median']:.2f}s)"
        if r.get("blas"):
            extra += f" BLAS {r.get('blas_lib')}"
    print(f"{r['kind']:5s} N={r['N']:5d} ranks={r['ranks']} v={r['v']:<5g} target={r['target']:<5g} "
          f"A/A0={r['area']:.4f} it={r['iterations']:5d} pairs={r['pairs']:8.1f} "
          f"t={r['seconds']:8.2f}s t/(pairs*pair)={tpp:5.2f} conv={r['converged']} res={r['residual']:.1e}"
          + extra, flush=True)


def _oracle_text(r):
    if r["oracle_pairs"] is None:
        return " oracle not run, overhead n/a"
    bound = "" if r["oracle_converged"] else " (oracle not converged: an upper bound)"
    if _restarted(r):
        bound += f" (oracle restarted every {r['oracle_restart']}: a lower bound)"
    text = (f" oracle it={r['oracle_iterations']} pairs={r['oracle_pairs']:.0f} "
            f"overhead={r['overhead']:.2f}{bound}")
    if r.get("oracle_matched_pairs") is not None:
        met = "" if r["oracle_matched_converged"] else f" (measure {r['oracle_matched_measure']:.1e} not met)"
        plain = r.get("oracle_measure")
        text += (f" (its measure {plain:.1e})" if plain is not None else "") + (
            f" matched it={r['oracle_matched_iterations']} pairs={r['oracle_matched_pairs']:.0f} "
            f"overhead_matched={r['overhead_matched']:.2f}{met}")
    return text


def _restarted(r):
    """Whether the case's oracle restarted (records before session 63 ran it at the steps' restart and
    do not say)."""
    return r.get("oracle_restart") is not None and r["oracle_iterations"] > r["oracle_restart"]


def summarise(records):
    """The JSON summary; with --blas the headline figures are the reference BLAS's and ``blas`` compares."""
    out = _summarise_one([r for r in records if r.get("blas") in (None, "reference")])
    labels = sorted({r["blas"] for r in records if r.get("blas") not in (None, "reference")})
    if labels:
        ref = {(r["N"], r["v"], r["target"]): r for r in records if r["kind"] == "snes" and r["blas"] == "reference"}
        out["blas"] = {}
        for lab in labels:
            alt = [r for r in records if r.get("blas") == lab]
            cases = [dict(N=r["N"], v=r["v"], target=r["target"], seconds_ratio=r["seconds"] / ref[k]["seconds"],
                          pairs_ratio=r["pairs"] / ref[k]["pairs"],
                          tpp_ratio=(r["seconds"] / r["pairs"]) / (ref[k]["seconds"] / ref[k]["pairs"]))
                     for r in alt if r["kind"] == "snes" and (k := (r["N"], r["v"], r["target"])) in ref]
            one = _summarise_one(alt)
            out["blas"][lab] = dict(time_per_pair_ratio=one["time_per_pair_ratio"],
                                    time_per_pair_ratio_median=one["time_per_pair_ratio_median"],
                                    loaded=sorted({r.get("blas_lib") for r in alt if r["kind"] == "snes"}),
                                    cases=cases)
            for c in cases:
                print(f"BLAS {lab} / reference: N={c['N']} v={c['v']:g} target={c['target']:g} seconds "
                      f"{c['seconds_ratio']:.3f} pairs {c['pairs_ratio']:.3f} seconds per pair {c['tpp_ratio']:.3f}")
    return out


def _summarise_one(records):
    sn = [r for r in records if r["kind"] == "snes"]
    pk = {(r["N"], r["target"]): r for r in records if r["kind"] == "pk"}
    ratios, iratios, tpp, paced, outside, inside = [], [], [], [], [], []
    for r in sn:
        if r["N"] >= 1024 and (r["N"], r["target"]) in pk:
            p = pk[(r["N"], r["target"])]
            ratios.append(r["pairs"] / p["pairs"])
            iratios.append(r["pairs"] / max(p["iterations"], 1))
        if r["N"] >= 1024:
            tpp.append(_per_pair(r, r["seconds"], r["t_pair"]))
            if r.get("t_pair_case"):
                paced.append(_per_pair(r, r["seconds"], r["t_pair_case"]))
            if r.get("pair_seconds"):
                outside.append(r["seconds"] / r["pair_seconds"])
                inside.append(_per_pair(r, r["pair_seconds"], r["t_pair"]))
    sizes = sorted({r["N"] for r in sn})
    growth = []
    if sizes:
        lo, hi = sizes[0], sizes[-1]
        by = {(r["N"], r["v"], r["target"]): r for r in sn}
        for (n, v, a), r in by.items():
            if n == hi and (lo, v, a) in by and hi > lo:
                growth.append(r["pairs"] / by[(lo, v, a)]["pairs"])
    # the overhead where the oracle converged; where it stopped at its cap, only an upper bound
    overhead = [r["overhead"] for r in sn if r["oracle_converged"]]
    bounds = [dict(N=r["N"], v=r["v"], target=r["target"], overhead_below=r["overhead"])
              for r in sn if r["oracle_converged"] is False]
    matched = [r["overhead_matched"] for r in sn if r.get("oracle_matched_converged")]
    s4096 = [r["seconds"] for r in sn if r["N"] == 4096 and abs(r["target"] - 0.05) < 1e-9 and r["ranks"] == 2]
    out = dict(
        pk_ratio_max=max(ratios) if ratios else None,
        pk_ratio_median=median(ratios) if ratios else None,
        pk_iter_ratio_max=max(iratios) if iratios else None,
        pairs_growth=max(growth) if growth else None,
        pairs_growth_sizes=[sizes[0], sizes[-1]] if sizes else None,
        time_per_pair_ratio=max(tpp) if tpp else None,
        time_per_pair_ratio_median=median(tpp) if tpp else None,
        time_per_pair_ratio_paced=max(paced) if paced else None,
        time_per_pair_ratio_paced_median=median(paced) if paced else None,
        solve_over_pairs_max=max(outside) if outside else None,
        pair_in_solve_ratio_max=max(inside) if inside else None,
        seconds_4096=max(s4096) if s4096 else None,
        overhead_max=max(overhead) if overhead else None,
        overhead_median=median(overhead) if overhead else None,
        overhead_bounds=bounds,
        overhead_restarted=[dict(N=r["N"], v=r["v"], target=r["target"], overhead_at_least=r["overhead"])
                            for r in sn if r["oracle_converged"] and _restarted(r)],
        overhead_cases=f"{len(overhead)} of {len(sn)}",
        overhead_matched_max=max(matched) if matched else None,
        overhead_matched_median=median(matched) if matched else None,
        overhead_matched_cases=f"{len(matched)} of {len(sn)}",
        all_converged=all(r["converged"] for r in records if r["kind"] in ("snes", "pk")),
        targets=dict(pk_ratio_max=0.5, pairs_growth=1.5, time_per_pair_ratio=1.3, seconds_4096=60, overhead_max=2),
    )
    return out


if __name__ == "__main__":
    main()
