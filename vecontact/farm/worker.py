"""A group's loop: ask for work, solve the cases of a chain in order, split when told, stop.

Each case is warm-started from the previous case of its chain when the group solved that one
just before; a group keeps its slab FFT (per N) and its surface (per (q1, seed)) between cases and
drops both when it splits (the communicator changes). Only the leader's row and fields link reach
the coordinator.

Test hook: ``VECONTACT_TEST_FAULT="<world rank>:<case index or name>[,...]"`` raises inside the solve
of that case on that rank (after the FFT and surface set-up, before the solver).
"""
import os
import time

from vecontact.farm.case import Setup, solve_case
from vecontact.farm.schedule import Finished, Split, Stop, split_range
from vecontact.rows import diagnostics

FAULT_ENV = "VECONTACT_TEST_FAULT"


def fault_targets(cases, spec=None):
    """Parse ``VECONTACT_TEST_FAULT`` (or ``spec``): set of (world rank, case index)."""
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


class Worker:
    """One rank's part in the farm: the job's cases and theory ``rows`` (case key -> row), the
    ``chains``, the grid per q1 ``Ns``, the spectra ``psds`` (q1 -> PSD) and its ``link`` to the hub."""

    def __init__(self, job, comm, link, cases, rows, psds, Ns, chains, petsc_options):
        self.comm = comm
        self.rank = comm.rank
        self.link = link
        self.cases = cases
        self.rows = rows
        self.psds = psds
        self.Ns = Ns
        self.chains = chains
        self.surface_spec = job.surface
        self.threads = job.numerics.threads
        self.planner = job.numerics.fft_planner or "measure"
        self.setup = Setup.from_job(job, petsc_options)
        self.faults = fault_targets(cases)
        self.busy = 0.0             # s spent solving
        self.current = None         # (case index, group size) for failure messages
        self._fft = None            # (N, SlabFFT)
        self._surface = None        # ((q1, seed), local heights)

    def run(self, group):
        """Solve what the coordinator hands this group until it says Stop."""
        prev = None             # (chain, position, ContactResult) for warm starts
        action = self.link.ask(group)
        while not isinstance(action, Stop):
            if isinstance(action, Split):
                G, k = group.size, action.k
                color = next(i for i in range(k) if split_range(G, k, i)[0] <= group.rank < split_range(G, k, i)[1])
                group = group.Split(color, key=group.rank)
                prev, self._fft, self._surface = None, None, None
                action = self.link.ask(group)
                continue
            chain, pos = action.chain, action.start
            warm = prev[2] if prev is not None and prev[:2] == (chain, pos - 1) else None
            prev = None
            t = time.perf_counter()
            res, row, link, pace = self.solve(group, self.chains[chain].cases[pos], warm)
            self.busy += time.perf_counter() - t
            prev = (chain, pos, res)
            action = self.link.ask(group, Finished(chain, pos, row, link, diagnostics(res, raw_pair_seconds=pace))
                                   if group.rank == 0 else None)

    def solve(self, group, idx, warm):
        """Case ``idx`` on the group: (ContactResult, row, fields link, raw pair seconds): solve_case."""
        case = self.cases[idx]
        self.current = (idx, group.size)
        fft = self.fft(group, self.Ns[case.q1])
        h = self.surface(fft, case.q1, case.seed)
        if (self.rank, idx) in self.faults:
            raise RuntimeError(f"{FAULT_ENV}: injected fault in case {idx} on rank {self.rank}")
        out = solve_case(group, fft, h, case, self.rows[case.key], self.setup, warm)
        self.current = None
        return out

    def fft(self, group, N):
        if self._fft is None or self._fft[0] != N:
            from vecontact.core.pfft import SlabFFT
            self._fft, self._surface = None, None
            self._fft = (N, SlabFFT(group, N, threads=self.threads, planner=self.planner))
        return self._fft[1]

    def surface(self, fft, q1, seed):
        key = (q1, seed)
        if self._surface is None or self._surface[0] != key:
            self._surface = None
            s = self.surface_spec
            if s.spectrum == "file":
                from vecontact.core.surface import load
                h = load(fft, s.file, s.dataset)
            else:
                from vecontact.core.surface import generate
                h = generate(fft, self.setup.L, self.psds[q1], seed, amplitudes=s.amplitudes)
            self._surface = (key, h)
        return self._surface[1]

    def fail(self, exc_text):
        """Report an exception (naming the case being solved): the hub prints it once and aborts."""
        if self.current is not None:
            idx, gsize = self.current
            c = self.cases[idx]
            head = (f"vecontact: error: case {idx} ({c.name}: q1={c.q1:g} seed={c.seed} v={c.velocity:g} "
                    f"p={c.pressure:g}) failed on rank {self.rank} (group of {gsize} ranks):\n")
        else:
            head = f"vecontact: error: the task farm failed on rank {self.rank}:\n"
        self.link.fail(head + exc_text)
