"""The MPI task farm: solves a job's numerical cases on any number of ranks.

Work units
----------
Cases at the same (q1, seed, velocity) form a *chain* of rising pressure: each solve is warm-started
from the previous one (``warm=``). A chain (or a piece of one) is the unit of work. Cases at the same
(q1, seed) share one generated surface per group (cached).

Groups
------
``COMM_WORLD`` is split into groups; a group solves one case at a time on all its ranks (slab FFT).
The ranks a case needs, g(N), come from ``numerics.ranks_per_case`` or, with ``auto``, from the grid:
g = 1 up to N = 1024 and beyond that the smallest power of two keeping <= 1024^2 grid points per rank
(N = 2048 -> 4, 4096 -> 16, 8192 -> 64); never more than N/2 (the slab FFT's limit) nor than the
ranks available. The farm starts with one group of all ranks; a group handed work that needs fewer
ranks splits itself (``Comm.Split``, local to the group) into floor(G/g) groups. Work is handed out
largest first (g, then N, then chain length), so group sizes only ever shrink and the largest grids
never start last.

Coordinator
-----------
World rank 0 runs the coordinator in a thread (``MPI_THREAD_MULTIPLE``; with a lower thread level
rank 0 is a dedicated coordinator and does not compute). The leader of every group asks it for work
and reports each finished case (its results row, a few hundred bytes). The coordinator owns the
results file (one writer): it adds each row and commits the file atomically (rows arriving during a
commit go into the next one). When the queue is empty an idle group *steals* the unstarted half of
the running chain with the most work left: the owner learns of its shorter range when it reports
its next case, so nothing is ever solved twice. Fields (``numerics.fields``) are gathered to and
written by the group leader (its own file, atomically); the coordinator only links them.

Failures
--------
A non-converged case is recorded (status -1) and the farm goes on. An exception on any rank is sent
to the coordinator, which commits the finished cases, prints the case and the traceback once and
calls ``MPI_Abort``: the job ends promptly (no rank is left waiting in a collective).
Test hook: ``VECONTACT_TEST_FAULT="<world rank>:<case index or name>[,...]"`` raises inside the solve
of that case on that rank.

Every wait here polls with short sleeps instead of blocking in MPI (MPICH spins in blocking calls):
idle ranks and the coordinator thread leave the cores to the ranks that compute.
"""
import math
import os
import sys
import threading
import time
import traceback
from collections import deque
from dataclasses import dataclass

import numpy as np
from mpi4py import MPI

from vecontact.io.results import write_fields_file

STOP, WORK, SPLIT = 0, 1, 2
TAG_REQ, TAG_REP, TAG_FAIL = 7101, 7102, 7103
AUTO_POINTS_PER_RANK = 1024 * 1024
FAULT_ENV = "VECONTACT_TEST_FAULT"
ABORT_DELAY = 1.0   # s between printing an error and MPI_Abort
COMMIT_RETRIES, COMMIT_RETRY_DELAY = 3, 2.0   # transient write errors of the results file
FAIL_GRACE = 20.0   # s a failing rank waits for the coordinator to abort before aborting itself
MORPHOLOGY_COLUMNS = ("patches", "percolating", "mean_patch_area", "perimeter", "anisotropy_extent",
                      "anisotropy_moments")


# ------------------------------------------------------------------------------------------------
# scheduling rules (pure functions, unit-tested)
def ranks_for_grid(N, nranks, ranks_per_case="auto"):
    """Ranks per case for an N x N grid with ``nranks`` ranks available (see the module doc)."""
    N = int(N)
    cap = max(1, min(N // 2, int(nranks)))
    if ranks_per_case == "auto":
        need = N * N / AUTO_POINTS_PER_RANK
        g = 1 if need <= 1 else 2 ** math.ceil(math.log2(need) - 1e-12)
    else:
        g = int(ranks_per_case)
    return max(1, min(g, cap))


def case_weight(N):
    """Relative cost of one case on an N x N grid: FFT pairs x N^2 log N with pairs ~ N^0.5."""
    N = float(N)
    return N * N * math.log2(N * N) * math.sqrt(N)


def split_factor(G, g, N):
    """Into how many groups a group of G ranks splits for work needing g ranks on an N grid."""
    cap = max(1, int(N) // 2)
    return max(1, G // max(1, g), -(-G // cap))


def split_range(n, size, rank):
    base, rem = divmod(n, size)
    start = rank * base + min(rank, rem)
    return start, start + base + (1 if rank < rem else 0)


@dataclass
class Chain:
    cid: int
    key: tuple          # (q1, seed, velocity)
    cases: list         # global case indices, rising pressure
    N: int
    g: int

    @property
    def weight(self):
        return len(self.cases) * case_weight(self.N)


def build_chains(cases, todo, grid_of, nranks, ranks_per_case="auto"):
    """Chains of the unfinished cases (``todo``: booleans), ordered largest first."""
    by_key = {}
    for i, c in enumerate(cases):
        if todo[i]:
            by_key.setdefault((c.q1, c.seed, c.velocity), []).append(i)
    chains = []
    for key, idx in by_key.items():
        idx.sort(key=lambda i: cases[i].pressure)
        N = grid_of(key[0])
        chains.append(Chain(-1, key, idx, N, ranks_for_grid(N, nranks, ranks_per_case)))
    chains.sort(key=lambda ch: (-ch.g, -ch.N, -len(ch.cases), ch.key))
    for k, ch in enumerate(chains):
        ch.cid = k
    return chains


def fault_targets(cases, spec=None):
    """Parse ``VECONTACT_TEST_FAULT``: set of (world rank, case index)."""
    spec = os.environ.get(FAULT_ENV, "") if spec is None else spec
    names = {c.name: i for i, c in enumerate(cases)}
    out = set()
    for item in filter(None, (s.strip() for s in spec.split(","))):
        rank, _, what = item.partition(":")
        try:
            r = int(rank)
        except ValueError:
            continue
        if what.strip().lstrip("-").isdigit():
            out.add((r, int(what)))
        elif what.strip() in names:
            out.add((r, names[what.strip()]))
    return out


def _pressure_places(cases):
    """Index of each case's pressure within its (q1, seed, velocity) sweep (0 = lowest)."""
    groups = {}
    for i, c in enumerate(cases):
        groups.setdefault((c.q1, c.seed, c.velocity), []).append(i)
    place = [0] * len(cases)
    for idx in groups.values():
        for k, i in enumerate(sorted(idx, key=lambda i: cases[i].pressure)):
            place[i] = k
    return place


def _hms(seconds):
    if seconds is None or not math.isfinite(seconds):
        return "?"
    s = int(round(seconds))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}"


# ------------------------------------------------------------------------------------------------
class Coordinator:
    """Hands out work and records finished rows. Pure bookkeeping: no MPI (the hub does transport).

    ``request(leader, gsize, finished)`` is the whole protocol: a group leader (identified by its
    world rank) of a group of ``gsize`` ranks reports ``finished`` = (chain id, position, row,
    fields link, solver diagnostics dict) or None, and gets the group's next action: (WORK, chain, position),
    (SPLIT, k, 0) or (STOP, 0, 0).
    """

    def __init__(self, chains, cases, writer=None, ndone=0, nranks=1, quiet=True, out=None, clock=time.time):
        self.chains = chains
        self.cases = cases
        self.writer = writer
        self.queue = deque([ch.cid, 0, len(ch.cases)] for ch in chains)
        self.running = {}           # leader -> [cid, current position, stop]
        self.active = 1             # groups alive: the farm starts with one
        self.lock = threading.RLock()
        self.dirty = False
        self.commits = 0
        self.commit_seconds = 0.0
        self.steals = 0
        self.splits = 0
        self.ndone = ndone          # rows in the file, previous runs included
        self.nsolved = 0            # solved by this run
        self.nfailed = 0
        self.ntotal = len(cases)
        self.nranks = max(1, nranks)
        self.quiet = quiet
        self.out = out if out is not None else sys.stdout
        self.clock = clock
        self.t0 = clock()
        # ETA: measured core-seconds per (N, place of the pressure in its sweep) and per N
        self.place = _pressure_places(cases)
        self.core_seconds = {}      # (N, place) and N -> [sum of seconds x ranks, count]
        self.left = {}              # (N, place) -> cases not yet solved
        for ch in chains:
            for i in ch.cases:
                k = (ch.N, self.place[i])
                self.left[k] = self.left.get(k, 0) + 1
        self.log = []               # (leader, action) for tests

    # --------------------------------------------------------------------------------------------
    def request(self, leader, gsize, finished=None):
        with self.lock:
            if finished is not None:
                cid, pos = finished[0], finished[1]
                self._record(*finished)
                item = self.running.get(leader)
                if item is not None and item[0] == cid and pos + 1 < item[2]:
                    item[1] = pos + 1
                    return self._note(leader, (WORK, cid, pos + 1))
                self.running.pop(leader, None)
            return self._note(leader, self._assign(leader, gsize))

    def _note(self, leader, action):
        self.log.append((leader, action))
        return action

    def _assign(self, leader, gsize):
        if self.queue:
            cid, start, stop = self.queue[0]
            ch = self.chains[cid]
            k = split_factor(gsize, ch.g, ch.N)
            if k > 1:
                return self._split(k)
            self.queue.popleft()
            self.running[leader] = [cid, start, stop]
            return (WORK, cid, start)
        # nothing queued: take the unstarted half of the running chain with the most work left
        best = None
        for other, (cid, cur, stop) in self.running.items():
            ch = self.chains[cid]
            unstarted = stop - cur - 1
            if unstarted < 1 or ch.g > gsize:
                continue
            w = unstarted * case_weight(ch.N)
            if best is None or w > best[0]:
                best = (w, other)
        if best is not None:
            item = self.running[best[1]]
            ch = self.chains[item[0]]
            k = split_factor(gsize, ch.g, ch.N)
            if k > 1:
                return self._split(k)
            cid, cur, stop = item
            mid = cur + 1 + (stop - cur - 1) // 2
            item[2] = mid
            self.running[leader] = [cid, mid, stop]
            self.steals += 1
            return (WORK, cid, mid)
        self.active -= 1
        return (STOP, 0, 0)

    def _split(self, k):
        self.active += k - 1
        self.splits += 1
        return (SPLIT, k, 0)

    # --------------------------------------------------------------------------------------------
    def _record(self, cid, pos, row, link=None, diagnostics=None):
        ch = self.chains[cid]
        idx = ch.cases[pos]
        reason = (diagnostics or {}).get("reason", "")
        if self.writer is not None:
            self.writer.add_row(row, diagnostics=diagnostics or None)
            if link:
                self.writer.link_fields(self.cases[idx].name, link)
        self.dirty = True
        self.ndone += 1
        self.nsolved += 1
        self.left[(ch.N, self.place[idx])] -= 1
        ok = int(row["status"]) == 1
        if not ok:
            self.nfailed += 1
        cs = float(row["seconds"]) * max(1, int(row["ranks"]))
        for key in (ch.N, (ch.N, self.place[idx])):
            acc = self.core_seconds.setdefault(key, [0.0, 0])
            acc[0] += cs
            acc[1] += 1
        if not self.quiet:
            print(self.progress_line(idx, row, reason), file=self.out, flush=True)

    def eta(self):
        """Seconds left: unsolved cases x measured core-seconds per case / ranks. A case is estimated
        from the cases at the same N and place in the pressure sweep (the area, hence the work,
        grows along it), else from all cases at that N, else scaled from another N by case_weight."""
        per_n = {k: s / n for k, (s, n) in self.core_seconds.items() if not isinstance(k, tuple)}
        if not per_n:
            return None
        ref = max(per_n)
        total = 0.0
        for (N, place), n in self.left.items():
            if n <= 0:
                continue
            acc = self.core_seconds.get((N, place))
            if acc is not None:
                est = acc[0] / acc[1]
            elif N in per_n:
                est = per_n[N]
            else:
                est = per_n[ref] * case_weight(N) / case_weight(ref)
            total += n * est
        return total / self.nranks

    def progress_line(self, idx, row, reason=""):
        c = self.cases[idx]
        w = len(str(self.ntotal))
        ok = int(row["status"]) == 1
        flag = "" if ok else f"  NOT CONVERGED (residual {float(row['residual']):.2e}{', ' + reason if reason else ''})"
        return (f"[{self.ndone:{w}d}/{self.ntotal}] q1={c.q1:.4g} seed={c.seed} v={c.velocity:.4g} "
                f"p={c.pressure:.4g}  A/A0={float(row['area']):.5f} mu={float(row['mu']):.5f} "
                f"it={int(row['iterations'])} {float(row['seconds']):.2f}s N={int(row['N'])}x{int(row['ranks'])}r"
                f"  ETA {_hms(self.eta())}{flag}")

    def commit_pending(self):
        """Commit the results file if rows arrived since the last commit. Returns True if it did."""
        with self.lock:
            if not self.dirty:
                return False
            if self.writer is not None:
                t = time.perf_counter()
                self.writer.commit()
                self.commit_seconds += time.perf_counter() - t
                self.commits += 1
            self.dirty = False
            return True


# ------------------------------------------------------------------------------------------------
def _wait(test, lo=1e-4, hi=5e-3):
    """Poll ``test()`` with growing sleeps (never spin in MPI)."""
    d = lo
    while not test():
        time.sleep(d)
        d = min(2 * d, hi)


class _Hub:
    """Transport of the coordinator on world rank 0: in-process for rank 0's own group, messages
    (polled, in a thread or in the main thread) for the others; also the single point of abort."""

    def __init__(self, coord, ctl, comm, threaded):
        self.coord = coord
        self.ctl = ctl
        self.comm = comm
        self.threaded = threaded
        self.thread = None
        self._abort_lock = threading.Lock()
        self.aborting = False
        self.busy = 0.0

    def start(self):
        self.thread = threading.Thread(target=self.loop, name="vecontact-coordinator", daemon=True)
        self.thread.start()

    def loop(self):
        try:
            d = 1e-4
            failures = 0
            st = MPI.Status()
            while True:
                if self.ctl.Iprobe(source=MPI.ANY_SOURCE, tag=MPI.ANY_TAG, status=st):
                    t = time.perf_counter()
                    src, tag = st.Get_source(), st.Get_tag()
                    msg = self.ctl.recv(source=src, tag=tag)
                    if tag == TAG_FAIL:
                        self.abort(msg)
                    elif tag == TAG_REQ:
                        gsize, finished = msg
                        action = self.coord.request(src, gsize, finished)
                        self.ctl.send(action, dest=src, tag=TAG_REP)
                    self.busy += time.perf_counter() - t
                    d = 1e-4
                    continue
                t = time.perf_counter()
                try:
                    committed = self.coord.commit_pending()
                    failures = 0
                except OSError as exc:      # e.g. a file-system hiccup: retry, then give up
                    failures += 1
                    if failures > COMMIT_RETRIES:
                        raise
                    sys.stderr.write(f"vecontact: warning: writing the results file failed ({exc}); "
                                     f"retrying in {COMMIT_RETRY_DELAY:g} s\n")
                    sys.stderr.flush()
                    time.sleep(COMMIT_RETRY_DELAY)
                    continue
                if committed:
                    self.busy += time.perf_counter() - t
                    continue
                if self.coord.active <= 0:
                    break
                time.sleep(d)
                d = min(2 * d, 1e-2)
        except BaseException:
            self.abort("vecontact: error: the coordinator / results writer on rank 0 failed:\n"
                       + traceback.format_exc())

    def abort(self, text):
        """Commit what is finished, print ``text`` once, end the whole job."""
        with self._abort_lock:
            if self.aborting:
                while True:
                    time.sleep(1)
            self.aborting = True
        kept = ""
        try:
            if self.coord.lock.acquire(timeout=30):
                try:
                    self.coord.commit_pending()
                    kept = (f"vecontact: job aborted; {self.coord.ndone} finished cases are kept in the results "
                            "file: rerun the same command to resume\n")
                finally:
                    self.coord.lock.release()
        except BaseException:
            kept = "vecontact: job aborted; committing the finished cases failed too\n"
        _abort(self.comm, text.rstrip("\n") + "\n" + kept)


def _abort(comm, text):
    try:
        sys.stdout.flush()
    except Exception:
        pass
    sys.stderr.write(text)
    sys.stderr.flush()
    if comm.size == 1:
        raise SystemExit(1)
    # mpiexec (hydra) tears the job down as soon as it hears of the abort and can drop output still
    # in flight from the ranks: give it a moment to forward the message first
    time.sleep(ABORT_DELAY)
    comm.Abort(1)


# ------------------------------------------------------------------------------------------------
class _Farm:
    """Everything one rank needs: job, cases, its group, the caches and the link to the coordinator."""

    def __init__(self, job, comm, cases, rows, psds, Ns, chains, petsc_options, hub, coord_rank_computes):
        self.job = job
        self.Ns = Ns
        self.comm = comm
        self.cases = cases
        self.rows = rows
        self.psds = psds
        self.chains = chains
        self.petsc_options = petsc_options
        self.hub = hub
        self.computes = coord_rank_computes
        self.rank = comm.rank
        self.ctl = hub.ctl if hub is not None else None
        self.faults = fault_targets(cases)
        num = job["numerics"]
        self.fields = list(num["fields"])
        self.downsample = int(num["downsample"])
        # the pressure always: its contact set gives the morphology columns
        self.store = tuple(f for f in ("pressure", "gap", "displacement") if f in self.fields or f == "pressure")
        from vecontact.physics.modulus import make_modulus
        self.modulus = make_modulus(job["material"])
        s = job["surface"]
        self.file_surface = s["spectrum"] == "file"
        self.L = s["length"] if self.file_surface else 2.0 * np.pi / s["q0"]
        self.busy = 0.0
        self.solve_seconds = 0.0
        self.nsolved = 0
        self.current = None         # (case index, group size) for failure messages
        self._fft = None            # (N, SlabFFT)
        self._surface = None        # ((q1, seed), local heights)

    # --------------------------------------------------------------------------------------------
    def ask(self, group, finished, buf):
        """The group's next action: the leader asks the coordinator, the group hears it (Ibcast)."""
        if group.rank == 0:
            if self.rank == 0:
                action = self.hub_request(group.size, finished)
            else:
                self.ctl.send((group.size, finished), dest=0, tag=TAG_REQ)
                _wait(lambda: self.ctl.Iprobe(source=0, tag=TAG_REP))
                action = self.ctl.recv(source=0, tag=TAG_REP)
            buf[:] = action
        if group.size > 1:
            _wait(group.Ibcast(buf, root=0).Test)
        return int(buf[0]), int(buf[1]), int(buf[2])

    def hub_request(self, gsize, finished):
        coord = self.hub.coord
        action = coord.request(0, gsize, finished)
        if self.hub.thread is None:     # one rank: no coordinator thread, commit here
            coord.commit_pending()
        return action

    def work(self, group):
        buf = np.zeros(3, dtype=np.int64)
        prev = None             # (cid, pos, ContactResult) for warm starts
        action = self.ask(group, None, buf)
        while True:
            kind, a, b = action
            if kind == STOP:
                return
            if kind == SPLIT:
                G = group.size
                color = next(i for i in range(a) if split_range(G, a, i)[0] <= group.rank < split_range(G, a, i)[1])
                group = group.Split(color, key=group.rank)
                prev, self._fft, self._surface = None, None, None
                action = self.ask(group, None, buf)
                continue
            cid, pos = a, b
            warm = prev[2] if prev is not None and prev[0] == cid and prev[1] == pos - 1 else None
            prev = None
            t = time.perf_counter()
            res, row, link = self.solve(group, self.chains[cid].cases[pos], warm)
            self.busy += time.perf_counter() - t
            prev = (cid, pos, res)
            action = self.ask(group, (cid, pos, row, link, solver_diagnostics(res)) if group.rank == 0 else None,
                              buf)

    # --------------------------------------------------------------------------------------------
    def fft(self, group, N):
        if self._fft is None or self._fft[0] != N:
            from vecontact.core.pfft import SlabFFT
            self._fft, self._surface = None, None
            self._fft = (N, SlabFFT(group, N, threads=self.job["numerics"]["threads"]))
        return self._fft[1]

    def surface(self, fft, q1, seed):
        key = (q1, seed)
        if self._surface is None or self._surface[0] != key:
            self._surface = None
            s = self.job["surface"]
            if self.file_surface:
                from vecontact.core.surface import load
                h = load(fft, s["file"], s.get("dataset"))
            else:
                from vecontact.core.surface import generate
                h = generate(fft, self.L, self.psds[q1], seed, amplitudes=s["amplitudes"])
            self._surface = (key, h)
        return self._surface[1]

    def grid_of(self, q1):
        return self.Ns[q1]

    def solve(self, group, idx, warm):
        from vecontact.solver import solve_contact
        case = self.cases[idx]
        self.current = (idx, group.size)
        N = self.grid_of(case.q1)
        fft = self.fft(group, N)
        h = self.surface(fft, case.q1, case.seed)
        num = self.job["numerics"]
        if (self.rank, idx) in self.faults:
            raise RuntimeError(f"{FAULT_ENV}: injected fault in case {idx} on rank {self.rank}")
        res = solve_contact(fft, self.L, h, self.modulus, case.velocity, case.pressure,
                            tolerance=num["tolerance"], method=num["solver"],
                            petsc_options=self.petsc_options or None, warm=warm, coarse=num["coarse"],
                            max_iterations=num["max_iterations"], store=self.store)
        self.solve_seconds += float(res.seconds)
        self.nsolved += 1
        row = self.rows[case.key].copy()
        for k in ("area", "mu", "mu_geometric", "mean_gap", "rigid_position", "residual", "seconds",
                  "fft_pairs"):
            row[k] = float(getattr(res, k))
        row["converged"] = bool(res.converged)
        row["iterations"] = int(res.iterations)
        row["linear_iterations"] = int(res.linear_iterations)
        row["N"] = N
        row["ranks"] = group.size
        row["status"] = 1 if res.converged else -1
        contact = gather_rows(group, fft, (res.pressure > 0).astype(np.uint8))
        if group.rank == 0:
            from vecontact.analysis.morphology import contact_morphology
            m = contact_morphology(contact, self.L / N)
            for k in MORPHOLOGY_COLUMNS:
                row[k] = getattr(m, k)
        link = self.write_fields(group, fft, case, res, row) if self.fields else None
        self.current = None
        return res, row, link

    def write_fields(self, group, fft, case, res, row):
        """Gather every k-th point of each requested field to the leader, which writes the file."""
        k = self.downsample
        arrays = {}
        for name in self.fields:
            src = res.pressure if name == "contact" else getattr(res, name)
            if src is None:
                continue
            src = (np.asarray(src) > 0).astype(np.uint8) if name == "contact" else np.asarray(src, np.float64)
            arrays[name] = gather_rows(group, fft, src, k)
        if group.rank != 0:
            return None
        attrs = {"q1": case.q1, "seed": case.seed, "velocity": case.velocity, "pressure": case.pressure,
                 "N": fft.N, "downsample": k, "L": self.L, "spacing": self.L * k / fft.N,
                 "area": float(row["area"]), "mu": float(row["mu"]), "converged": bool(row["converged"]),
                 "units": "pressure: Pa; gap, displacement: m; contact: 1 where p > 0; spacing, L: m",
                 "layout": "[x, y], axis 0 = sliding direction x; every downsample-th grid point"}
        return write_fields_file(self.job["output"], case.name, arrays, attrs)

    # --------------------------------------------------------------------------------------------
    def fail(self, exc_text):
        """Report an exception: the coordinator prints it once and aborts the job."""
        if self.current is not None:
            idx, gsize = self.current
            c = self.cases[idx]
            head = (f"vecontact: error: case {idx} ({c.name}: q1={c.q1:g} seed={c.seed} v={c.velocity:g} "
                    f"p={c.pressure:g}) failed on rank {self.rank} (group of {gsize} ranks):\n")
        else:
            head = f"vecontact: error: the task farm failed on rank {self.rank}:\n"
        text = head + exc_text
        if self.rank == 0 and self.hub is not None and self.hub.coord is not None:
            self.hub.abort(text)
        if self.comm.size == 1 or self.ctl is None:
            _abort(self.comm, text)
        req = self.ctl.isend(text, dest=0, tag=TAG_FAIL)
        t0 = time.time()
        while time.time() - t0 < FAIL_GRACE:     # the coordinator aborts us all
            if req.Test():
                pass
            time.sleep(0.05)
        _abort(self.comm, text)


def gather_rows(group, fft, local, k=1):
    """Every k-th row and column of a slab-distributed field (local rows [row_start, row_stop) of an
    N x N grid), gathered to the group's rank 0 (None elsewhere). uint8 or float64 fields."""
    first = -(-fft.row_start // k) * k
    part = np.ascontiguousarray(local[np.arange(first, fft.row_stop, k) - fft.row_start, ::k])
    if group.size == 1:
        return part
    nrows = np.array(group.allgather(part.shape[0]))
    counts = nrows * part.shape[1]
    displs = np.concatenate([[0], np.cumsum(counts)[:-1]])
    full = np.empty((int(nrows.sum()), part.shape[1]), part.dtype) if group.rank == 0 else None
    mpitype = MPI.UNSIGNED_CHAR if part.dtype == np.uint8 else MPI.DOUBLE
    group.Gatherv(part, [full, counts, displs, mpitype] if group.rank == 0 else None, root=0)
    return full


def solver_diagnostics(res):
    """What a row of /cases does not hold about a solve (stored in /diagnostics): the reason, the
    per-level Newton counts, the fine grid's residual history and active-set changes, FFT pairs per
    grid (fine-grid equivalents in /cases; here per level, unweighted)."""
    d = res.diagnostics
    return {"reason": res.reason, "method": res.method, "measures": res.measures,
            "fft_pairs_by_level": {str(k): v for k, v in res.fft_pairs_by_level.items()},
            "levels": d.get("levels", []), "history": d.get("history", []),
            "active_set_changes": d.get("active_set_changes", []),
            "linear_history": d.get("linear_history", []),
            "step_modes": d.get("step_modes", []),
            "kappa": d.get("kappa"), "ell": d.get("ell")}


def grid_of(job, q1):
    s = job["surface"]
    if s["spectrum"] == "file":
        from vecontact.io.surfaces import file_grid_size
        return file_grid_size(s["file"], s.get("dataset"))
    return s["grid"][repr(float(q1))]


def _petsc_options(job, petsc_args):
    """job's numerics.petsc merged with the command line's PETSc options (command line wins)."""
    from vecontact.solver.options import parse
    opts = dict(job["numerics"].get("petsc") or {})
    if petsc_args:
        opts.update(parse(list(petsc_args), "numerics.petsc"))
    return opts


def _first_commit(comm, writer):
    """Write the file (theory, finished rows) before any solve: an unwritable output is found now,
    as a one-line error on every rank, not after the first case."""
    err = None
    if comm.rank == 0 and writer is not None:
        try:
            writer.commit()
        except Exception as exc:
            err = f"cannot write {writer.path} ({type(exc).__name__}: {exc})"
    err = comm.bcast(err, root=0)
    if err:
        from vecontact.errors import ResultsFileError
        raise ResultsFileError("output", err)


def _init_petsc(job):
    """PetscInitialize is collective on COMM_WORLD: do it on every rank before the groups split."""
    if job["numerics"]["solver"] != "snes":
        return
    try:
        from petsc4py import PETSc  # noqa: F401
    except ImportError:
        pass


# ------------------------------------------------------------------------------------------------
def run_numerics(job, comm, writer, cases, rows, psds, quiet=False, petsc_args=(), only_q1=None):
    """Solve every unfinished case of the job on ``comm`` (only those at the q1 values in
    ``only_q1`` when it is given) and commit each row as it finishes."""
    t_start = time.perf_counter()
    petsc_options = _petsc_options(job, petsc_args)     # bad options: InputError on every rank
    rank, size = comm.rank, comm.size
    num = job["numerics"]
    todo = np.ones(len(cases), dtype=bool)
    if rank == 0 and writer is not None:
        done = writer.done()
        todo = np.array([c.key not in done for c in cases], dtype=bool)
    todo = comm.bcast(todo, root=0)
    if only_q1 is not None:
        todo &= np.array([c.q1 in only_q1 for c in cases], dtype=bool)
    if rank == 0 and writer is not None:
        writer.note_run(petsc_options=petsc_options, ranks_per_case=str(num["ranks_per_case"]))
    _first_commit(comm, writer)
    threaded = size == 1 or MPI.Query_thread() >= MPI.THREAD_MULTIPLE
    nwork = size if threaded else size - 1
    Ns = {q1: grid_of(job, q1) for q1 in psds}
    chains = build_chains(cases, todo, lambda q1: Ns[q1], nwork, num["ranks_per_case"])
    _init_petsc(job)
    ctl = comm.Dup()
    fin = comm.Dup()
    hub = coord = None
    if rank == 0:
        ndone = len(writer.done()) if writer is not None else 0
        coord = Coordinator(chains, cases, writer, ndone=ndone, nranks=nwork, quiet=quiet)
        if not quiet:
            rule = ", ".join(f"N={N}: {ranks_for_grid(N, nwork, num['ranks_per_case'])}"
                             for N in sorted(set(Ns.values())))
            print(f"farm: {len(cases)} cases, {ndone} already finished, {int(todo.sum())} to solve "
                  f"in {len(chains)} chains on {size} ranks (ranks per case, {num['ranks_per_case']}: {rule}; "
                  f"coordinator {'thread on rank 0' if threaded else 'on rank 0 (dedicated)'})", flush=True)
    hub = _Hub(coord, ctl, comm, threaded) if rank == 0 else _Hub(None, ctl, comm, threaded)
    farm = _Farm(job, comm, cases, rows, psds, Ns, chains, petsc_options, hub, threaded)
    try:
        if threaded:
            if rank == 0 and size > 1:
                hub.start()
            group = comm.Dup()
            farm.work(group)
            if rank == 0 and hub.thread is not None:
                while hub.thread.is_alive():
                    hub.thread.join(0.05)
        else:
            group = comm.Split(0 if rank > 0 else MPI.UNDEFINED, key=rank)
            if rank == 0:
                hub.loop()
            else:
                farm.work(group)
    except BaseException:
        farm.fail(traceback.format_exc())
    # all groups stopped: the last rows, the summary
    if rank == 0:
        try:
            coord.commit_pending()
            if writer is not None:
                writer.commit(complete=len(writer.done()) >= len(cases))
        except BaseException:
            _abort(comm, "vecontact: error: writing the results file failed:\n" + traceback.format_exc())
    wall = time.perf_counter() - t_start
    stats = fin.gather((farm.busy, farm.solve_seconds, farm.nsolved), root=0)
    if rank == 0 and not quiet:
        _summary(coord, hub, stats, wall, size, threaded)
    _wait(fin.Ibarrier().Test, hi=2e-2)
    for c in (ctl, fin):
        c.Free()
    return coord.nsolved if coord is not None else None


def _summary(coord, hub, stats, wall, size, threaded):
    busy = np.array([s[0] for s in stats]) / max(wall, 1e-9)
    lines = [f"farm: solved {coord.nsolved} cases ({coord.nfailed} not converged) in {wall:.1f} s wall on "
             f"{size} ranks; {coord.splits} group splits, {coord.steals} chain splits; "
             f"{coord.commits} commits ({coord.commit_seconds:.2f} s); coordinator {hub.busy:.2f} s"]
    if size <= 16:
        per = "  ".join(f"{r}: {100 * b:.1f}%" for r, b in enumerate(busy))
    else:
        low = np.argsort(busy)[:5]
        per = "least busy " + "  ".join(f"{r}: {100 * busy[r]:.1f}%" for r in low)
    if not threaded:
        per += "  (rank 0 coordinates only)"
    lines.append(f"farm: busy fraction per rank: {per}  [min {100 * busy.min():.1f}%, "
                 f"mean {100 * busy.mean():.1f}%, max {100 * busy.max():.1f}%]")
    print("\n".join(lines), flush=True)
