"""The task farm's scheduling: pure rules and the coordinator (bookkeeping only: no MPI, no printing).

Work units
----------
Cases at the same (q1, seed, velocity) form a *chain* of rising pressure: each solve is warm-started
from the previous one. A chain (or a piece of one) is the unit of work. Cases at the same
(q1, seed) share one generated surface per group (cached by the worker).

Groups
------
``COMM_WORLD`` is split into groups; a group solves one case at a time on all its ranks (slab FFT).
The ranks a case needs, g(N), come from ``numerics.ranks_per_case`` or, with ``auto``, from memory:
the smallest power of two whose share of the case (memory.case_bytes) fits in MEMORY_USE of a rank's
share of its node (memory.memory_per_rank; 4096^2 -> 1 with 12 GB a rank, 8 with 4 GB, 16 with 3),
raised where a grid has fewer cases than ranks to nranks / cases, up to the grid rule's g below.
Where the node's memory is unknown, from the grid: g = 1 up to N = 1024 and beyond that the smallest
power of two keeping <= 1024^2 grid points per rank (N = 2048 -> 4, 4096 -> 16, 8192 -> 64). Never
more than N/2 (the slab FFT's limit) nor than the ranks available. The farm starts with one group
of all ranks; a group handed work that needs fewer ranks splits itself (``Comm.Split``, local to the
group) into floor(G/g) groups. Work is handed out largest first (g, then N, then chain length), so
group sizes only ever shrink and the largest grids never start last.

Messages
--------
A group's leader asks the coordinator with its group size and what it has just finished (a
:class:`Finished` report, or None) and gets the group's next action, one of

* ``Work(chain, start, stop)``: solve case ``start`` of that chain; the group's range of the chain
  is [start, stop) as the coordinator knows it now. The group reports each case and is told the
  next one, so a steal (below) that shortens the range reaches it at its next report;
* ``Split(k)``: split into k groups of contiguous ranks (:func:`split_range`) and ask again;
* ``Stop()``: nothing left for this group.

When the queue is empty an idle group *steals* the unstarted half of the running chain with the
most work left: nothing is ever solved twice. The coordinator owns the results file (one writer):
it adds each row and commits when asked (:meth:`Coordinator.commit_pending`; rows arriving during a
commit go into the next one). A non-converged case is recorded (status -1) like any other.
"""
import math
import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Any, NamedTuple, Optional

from vecontact.farm.memory import fits
from vecontact.rows import CONVERGED, REASON

AUTO_POINTS_PER_RANK = 1024 * 1024


# ------------------------------------------------------------------------------------------------
# messages
class Work(NamedTuple):
    """Solve case ``start`` of chain ``chain``; the group's range is [start, stop) for now."""
    chain: int
    start: int
    stop: int


class Split(NamedTuple):
    """Split the group into ``k`` groups of contiguous ranks, then each asks again."""
    k: int


class Stop(NamedTuple):
    """Nothing left for this group: it leaves the farm."""


class Finished(NamedTuple):
    """A leader's report: case ``position`` of chain ``chain`` is solved. ``row``: its /cases row;
    ``link``: its fields file relative to the results file's folder, or None; ``diagnostics``: a
    JSON-serialisable dict for /diagnostics, or None."""
    chain: int
    position: int
    row: Any
    link: Optional[str] = None
    diagnostics: Optional[dict] = None


# ------------------------------------------------------------------------------------------------
# rules
def ranks_for_grid(N, nranks, ranks_per_case="auto", memory=None, settings=None, count=None):
    """Ranks per case for an N x N grid with ``nranks`` ranks available (see the module doc);
    ``memory``: bytes a rank may use (memory.memory_per_rank), None where unknown; ``settings``: the
    job's SolverSettings, whose Krylov budgets enter the case's estimate (default: the defaults);
    ``count``: the grid's unfinished cases.  auto by memory never leaves ranks idle for want of cases:
    with fewer cases than ranks each gets up to nranks / count ranks (a power of two), but never more
    than the grid rule gives, beyond which more ranks stop paying."""
    N = int(N)
    cap = max(1, min(N // 2, int(nranks)))
    if ranks_per_case == "auto" and memory is not None:
        g = 1
        while g < cap and not fits(N, g, memory, settings):
            g *= 2
        if count:
            fill = min(_grid_ranks(N), nranks // count)
            while 2 * g <= fill:
                g *= 2
    elif ranks_per_case == "auto":
        g = _grid_ranks(N)
    else:
        g = int(ranks_per_case)
    return max(1, min(g, cap))


def _grid_ranks(N):
    """The grid rule: 1 up to AUTO_POINTS_PER_RANK points, else the smallest power of two keeping at
    most that many points a rank."""
    need = N * N / AUTO_POINTS_PER_RANK
    return 1 if need <= 1 else 2 ** math.ceil(math.log2(need) - 1e-12)


def case_weight(N):
    """Relative cost of one case on an N x N grid: FFT pairs x N^2 log N with pairs ~ N^0.5."""
    N = float(N)
    return N * N * math.log2(N * N) * math.sqrt(N)


def split_factor(G, g, N):
    """Into how many groups a group of G ranks splits for work needing g ranks on an N grid."""
    cap = max(1, int(N) // 2)
    return max(1, G // max(1, g), -(-G // cap))


def split_range(n, size, rank):
    """[start, stop) of part ``rank`` of ``n`` items in ``size`` contiguous parts (the first ones larger)."""
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


def build_chains(cases, todo, grid_of, nranks, ranks_per_case="auto", memory=None, settings=None):
    """Chains of the unfinished cases (``todo``: booleans), ordered largest first; ``memory`` and
    ``settings`` as in ranks_for_grid, which counts each grid's unfinished cases."""
    by_key = {}
    for i, c in enumerate(cases):
        if todo[i]:
            by_key.setdefault((c.q1, c.seed, c.velocity), []).append(i)
    grid = {key: grid_of(key[0]) for key in by_key}
    count = {}
    for key, idx in by_key.items():
        count[grid[key]] = count.get(grid[key], 0) + len(idx)
    chains = []
    for key, idx in by_key.items():
        idx.sort(key=lambda i: cases[i].pressure)
        N = grid[key]
        chains.append(Chain(-1, key, idx, N, ranks_for_grid(N, nranks, ranks_per_case, memory, settings, count[N])))
    chains.sort(key=lambda ch: (-ch.g, -ch.N, -len(ch.cases), ch.key))
    for k, ch in enumerate(chains):
        ch.cid = k
    return chains


# ------------------------------------------------------------------------------------------------
class Coordinator:
    """Hands out work and records finished rows. Pure bookkeeping: no MPI (the hub does transport).

    ``request(leader, gsize, finished)`` is the whole protocol: the leader of a group of ``gsize``
    ranks (identified by its world rank) reports ``finished`` (a :class:`Finished`, or None) and gets
    the group's next action: :class:`Work`, :class:`Split` or :class:`Stop`. ``progress`` (a
    :class:`vecontact.farm.progress.Progress`, or None) hears of every recorded case.
    """

    def __init__(self, chains, cases, writer=None, ndone=0, progress=None):
        self.chains = chains
        self.cases = cases
        self.writer = writer
        self.progress = progress
        self.queue = deque([ch.cid, 0, len(ch.cases)] for ch in chains)
        self.running = {}           # leader -> [cid, current position, stop]
        self.active = 1             # groups alive: the farm starts with one
        self.lock = threading.RLock()
        self.writing = None         # ident of the thread writing the results file, if any
        self.after_write = None     # called once that write is done (a signal deferred by it)
        self.dirty = False
        self.commits = 0
        self.commit_seconds = 0.0
        self.steals = 0
        self.splits = 0
        self.ndone = ndone          # rows in the file, previous runs included
        self.nsolved = 0            # solved by this run
        self.nfailed = 0
        self.log = []               # (leader, action) for tests

    # --------------------------------------------------------------------------------------------
    def request(self, leader, gsize, finished=None):
        with self.lock:
            if finished is not None:
                self._record(finished)
                item = self.running.get(leader)
                if item is not None and item[0] == finished.chain and finished.position + 1 < item[2]:
                    item[1] = finished.position + 1
                    return self._note(leader, Work(*item))
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
            return Work(cid, start, stop)
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
            return Work(cid, mid, stop)
        self.active -= 1
        return Stop()

    def _split(self, k):
        self.active += k - 1
        self.splits += 1
        return Split(k)

    # --------------------------------------------------------------------------------------------
    def _record(self, fin):
        idx = self.chains[fin.chain].cases[fin.position]
        if self.writer is not None:
            self.writer.add_row(fin.row, diagnostics=fin.diagnostics or None)
            if fin.link:
                self.writer.link_fields(self.cases[idx].name, fin.link)
        self.dirty = True
        self.ndone += 1
        self.nsolved += 1
        if int(fin.row["status"]) != CONVERGED:
            self.nfailed += 1
        if self.progress is not None:
            self.progress.record(idx, fin.row, (fin.diagnostics or {}).get(REASON, ""), self.ndone)

    def commit_pending(self, complete=None):
        """Commit the results file if rows arrived since the last commit; with ``complete`` (True or
        False) commit in any case, marking the file complete or not. Returns True if it did."""
        with self.lock:
            if not self.dirty and complete is None:
                return False
            if self.writer is not None:
                t = time.perf_counter()
                self.writing = threading.get_ident()
                try:
                    self.writer.commit(complete=bool(complete))
                finally:
                    self.writing = None
                self.commit_seconds += time.perf_counter() - t
                self.commits += 1
            self.dirty = False
        if self.after_write is not None:
            then, self.after_write = self.after_write, None
            then()
        return True
