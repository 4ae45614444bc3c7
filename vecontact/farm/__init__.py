"""The MPI task farm: solves a job's numerical cases on any number of ranks.

Cases at the same (q1, seed, velocity) form a chain of rising pressure, each case warm-started from
the previous one; groups of ranks (as many as a case's grid needs) solve chains, or halves of them,
largest first; world rank 0 coordinates and alone writes the results file.

Layers, one module each:

* :mod:`~vecontact.farm.schedule`: the pure rules (ranks per grid, chains, splits), the messages
  ``Work(chain, start, stop)``, ``Split(k)``, ``Stop()``, ``Finished(...)`` and the coordinator;
* :mod:`~vecontact.farm.transport`: the hub on rank 0, the ranks' links to it, polling waits, abort;
* :mod:`~vecontact.farm.worker`: a group's loop and its caches (FFT, surface);
* :mod:`~vecontact.farm.case`: one case solved and turned into its row (and fields file);
* :mod:`~vecontact.farm.interrupt`: Ctrl-C and SIGTERM (rank 0 commits and ends the job);
* :mod:`~vecontact.farm.progress`: the start line, progress lines with ETA, the summary;
* :mod:`~vecontact.farm.memory`: a node's available memory and a case's peak (``ranks_per_case: auto``);
* :mod:`~vecontact.farm.run`: :func:`run_numerics`, which puts them together.
"""
from vecontact.farm.case import gather_rows
from vecontact.farm.run import run_numerics
from vecontact.farm.worker import FAULT_ENV

__all__ = ["run_numerics", "gather_rows", "FAULT_ENV"]
