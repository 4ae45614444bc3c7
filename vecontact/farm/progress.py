"""What the task farm prints: the start line, one line per finished case with an ETA, the summary.

Users and tests read these lines ("farm: N cases, K already finished, M to solve ...", "[i/n] q1=",
"ETA", "NOT CONVERGED", "busy fraction per rank"): change their format only on purpose.

ETA: the unsolved cases times the measured core-seconds per case, over the ranks that compute. A
case is estimated from the finished cases at the same N and the same place in its pressure sweep
(the contact area, hence the work, grows along the sweep), else from all finished cases at that N,
else scaled from the largest N measured by :func:`~vecontact.farm.schedule.case_weight`.
"""
import math
import sys

import numpy as np

from vecontact.farm.schedule import case_weight
from vecontact.rows import CONVERGED


def hms(seconds):
    """``H:MM:SS`` of a duration in s ("?" when unknown)."""
    if seconds is None or not math.isfinite(seconds):
        return "?"
    s = int(round(seconds))
    return f"{s // 3600}:{s % 3600 // 60:02d}:{s % 60:02d}"


def pressure_places(cases):
    """Index of each case's pressure within its (q1, seed, velocity) sweep (0 = lowest)."""
    groups = {}
    for i, c in enumerate(cases):
        groups.setdefault((c.q1, c.seed, c.velocity), []).append(i)
    place = [0] * len(cases)
    for idx in groups.values():
        for k, i in enumerate(sorted(idx, key=lambda i: cases[i].pressure)):
            place[i] = k
    return place


class Progress:
    """Per-case progress lines of one run: ``cases`` of the job, the ``chains`` left to solve (their
    grids), ``nranks`` ranks that compute; lines go to ``out`` (stdout).  ``total``: the count the
    run's last line reaches, the file's finished cases plus this run's (``run --q1`` solves a part of
    the job); None: all the job's cases."""

    def __init__(self, cases, chains, nranks=1, out=None, total=None):
        self.cases = cases
        self.total = len(cases) if total is None else int(total)
        self.nranks = max(1, nranks)
        self.out = out if out is not None else sys.stdout
        self.place = pressure_places(cases)
        self.grid = {i: ch.N for ch in chains for i in ch.cases}
        self.core_seconds = {}      # (N, place) and N -> [sum of seconds x ranks, count]
        self.left = {}              # (N, place) -> cases not yet solved
        for i, N in self.grid.items():
            k = (N, self.place[i])
            self.left[k] = self.left.get(k, 0) + 1

    def record(self, idx, row, reason, ndone):
        """Case ``idx`` is solved (its /cases ``row``, the solver's ``reason``), the ``ndone``-th of
        the job: count its core-seconds and print its line."""
        N = self.grid[idx]
        self.left[(N, self.place[idx])] -= 1
        cs = float(row["seconds"]) * max(1, int(row["ranks"]))
        for key in (N, (N, self.place[idx])):
            acc = self.core_seconds.setdefault(key, [0.0, 0])
            acc[0] += cs
            acc[1] += 1
        print(self.line(idx, row, reason, ndone), file=self.out, flush=True)

    def eta(self):
        """Seconds left (see the module doc), or None before the first case."""
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

    def line(self, idx, row, reason="", ndone=0):
        """``[ndone/total] q1=... ETA H:MM:SS`` for case ``idx``, flagged when it did not converge."""
        c = self.cases[idx]
        w = len(str(self.total))
        ok = int(row["status"]) == CONVERGED
        flag = "" if ok else f"  NOT CONVERGED (residual {float(row['residual']):.2e}{', ' + reason if reason else ''})"
        return (f"[{ndone:{w}d}/{self.total}] q1={c.q1:.4g} seed={c.seed} v={c.velocity:.4g} "
                f"p={c.pressure:.4g}  A/A0={float(row['area']):.5f} mu={float(row['mu']):.5f} "
                f"it={int(row['iterations'])} {float(row['seconds']):.2f}s N={int(row['N'])}x{int(row['ranks'])}r"
                f"  ETA {hms(self.eta())}{flag}")


def start_line(ncases, ndone, nsolve, nchains, nranks, ranks_per_case, rule, threaded, memory=None):
    """The run's first line. ``rule``: {N: ranks per case}; ``threaded``: the coordinator is a
    thread on rank 0 (else rank 0 only coordinates); ``memory``: the bytes a rank may use that
    ``auto`` went by (None: unknown, the grid rule)."""
    rules = ", ".join(f"N={N}: {g}" for N, g in sorted(rule.items()))
    how = str(ranks_per_case)
    if ranks_per_case == "auto":
        how += (f" by memory, {memory / 1e9:.1f} GB a rank" if memory is not None
                else " by grid, the node's memory unknown")
    return (f"farm: {ncases} cases, {ndone} already finished, {nsolve} to solve "
            f"in {nchains} chains on {nranks} ranks (ranks per case, {how}: {rules}; "
            f"coordinator {'thread on rank 0' if threaded else 'on rank 0 (dedicated)'})")


def summary(coord, coordinator_seconds, busy_seconds, wall, threaded):
    """The run's last two lines: counts of the coordinator ``coord``, then the busy fraction per
    rank (``busy_seconds`` per world rank, of ``wall`` s)."""
    size = len(busy_seconds)
    busy = np.array(busy_seconds) / max(wall, 1e-9)
    lines = [f"farm: solved {coord.nsolved} cases ({coord.nfailed} not converged) in {wall:.1f} s wall on "
             f"{size} ranks; {coord.splits} group splits, {coord.steals} chain splits; "
             f"{coord.commits} commits ({coord.commit_seconds:.2f} s); coordinator {coordinator_seconds:.2f} s"]
    if size <= 16:
        per = "  ".join(f"{r}: {100 * b:.1f}%" for r, b in enumerate(busy))
    else:
        low = np.argsort(busy)[:5]
        per = "least busy " + "  ".join(f"{r}: {100 * busy[r]:.1f}%" for r in low)
    if not threaded:
        per += "  (rank 0 coordinates only)"
    lines.append(f"farm: busy fraction per rank: {per}  [min {100 * busy.min():.1f}%, "
                 f"mean {100 * busy.mean():.1f}%, max {100 * busy.max():.1f}%]")
    return "\n".join(lines)
