"""Memory, for ``numerics.ranks_per_case: auto``: what a rank may use on its node, what a case needs.

auto gives a grid the fewest ranks per case (a power of two) whose share of the case fits in one
rank's share of its node: a one-rank case does no transposes, and two one-rank cases at once cost
0.79-0.87x the core-seconds of the same cases on two ranks at 2048² and 4096²
(benchmarks/RESULTS.md, "One rank per case at 4096²"); the study's four 4096² chains, where a one-rank
case's half restart costs pairs at fast sliding, cost 0.78-0.85x on one rank a case the core-hours
they cost on two, 0.81x in all (RESULTS.md, "One rank or two per case, measured again" and "The
study's slow half").  Where the node's memory cannot be read, auto falls back to the grid rule
(schedule.AUTO_POINTS_PER_RANK) and the farm's start line says so.

Sizes are bytes.  The node's memory is Linux's MemAvailable, capped by the job's cgroup (v2
``memory.max`` less ``memory.current``, v1 ``memory.limit_in_bytes`` less ``memory.usage_in_bytes``,
on the process's group and its ancestors: what a batch scheduler grants).
"""
import os

from vecontact.solver.recycle import ComplianceKernel
from vecontact.solver.settings import SolverSettings

__all__ = ["case_bytes", "fits", "node_available", "memory_per_rank", "BYTES_PER_POINT", "KRYLOV_PEAK", "MEMORY_USE"]

# the solver's arrays per grid point of a case: 4.5e9 B peak at 4096² on 1 rank, 0.01 m/s, 4.5 % (6.0e9
# before session 37) [RESULTS.md, "Memory per grid point"]
BYTES_PER_POINT = 270
# peak Krylov memory over the basis of the restart rules: 8.1e9 B at 4096², 10 m/s, 27 % on 1 rank
# (9.7e9 before session 37, 10.1e9 in the farm's 4096² study) [RESULTS.md]
KRYLOV_PEAK = 1.4
# the part of a rank's share auto lets a case fill (the rest: the system, the farm, MPI's buffers)
MEMORY_USE = 0.9

_UNLIMITED = 2 ** 60


def case_bytes(N, g, settings=None):
    """Peak bytes per rank of an N x N case on ``g`` ranks: the arrays, and the largest Krylov basis the
    ``settings``' restart rules give a step: a free-set GMRES over all of a rank's points, or the
    contact-set steps' inner FGMRES (two vectors an iteration) over the largest contact set solved on
    (SolverSettings.widest_step_area of an N x N grid; all points with contact_step "contact"):
    SolverSettings.krylov_bytes.  That is their budgets (3 GB a rank by default), less where the
    restart caps bind, more where ``restart_min`` does; the VI steps' longer restart
    (vi_capped_restart) stays within it.  Plus the kernel of
    the contact-set steps' map of carried directions (recycle.py), N^2 float32 on every rank whatever
    ``g``, where it is made (within half of carry_memory)."""
    s = SolverSettings() if settings is None else settings
    n = float(N) * float(N) / max(1, int(g))
    kernel = ComplianceKernel.bytes(N) if ComplianceKernel.fits(N, s) else 0.0
    return BYTES_PER_POINT * n + KRYLOV_PEAK * s.krylov_bytes(N, n) + kernel


def fits(N, g, memory, settings=None):
    """Whether an N x N case's share on ``g`` ranks (case_bytes) fits in MEMORY_USE of ``memory``, the
    bytes a rank may use; True where ``memory`` is None (unknown)."""
    return memory is None or case_bytes(N, g, settings) <= MEMORY_USE * memory


def _read_int(path):
    try:
        with open(path) as fh:
            text = fh.read().strip()
    except OSError:
        return None
    if text == "max":
        return _UNLIMITED
    try:
        return int(text)
    except ValueError:
        return None


def _mem_available(meminfo):
    try:
        with open(meminfo) as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def _cgroup_room(proc_cgroup, cgroup_root):
    """The least room (limit less usage) over the process's memory cgroup and its ancestors, or None
    where no limit is set or nothing can be read."""
    try:
        with open(proc_cgroup) as fh:
            lines = fh.read().splitlines()
    except OSError:
        return None
    places = []
    for line in lines:
        parts = line.split(":", 2)
        if len(parts) != 3:
            continue
        hid, controllers, path = parts
        if hid == "0" and controllers == "":
            places.append((cgroup_root, path, "memory.max", "memory.current"))
        elif "memory" in controllers.split(","):
            places.append((os.path.join(cgroup_root, "memory"), path, "memory.limit_in_bytes",
                           "memory.usage_in_bytes"))
    room = None
    for root, path, limit_name, usage_name in places:
        rel = path.strip("/")
        while True:
            d = os.path.join(root, rel) if rel else root
            limit, usage = _read_int(os.path.join(d, limit_name)), _read_int(os.path.join(d, usage_name))
            if limit is not None and usage is not None and limit < _UNLIMITED:
                room = limit - usage if room is None else min(room, limit - usage)
            if not rel:
                break
            rel = os.path.dirname(rel)
    return room


def node_available(meminfo="/proc/meminfo", proc_cgroup="/proc/self/cgroup", cgroup_root="/sys/fs/cgroup"):
    """Bytes this node can still give the job (see the module doc), or None where MemAvailable cannot
    be read (not Linux)."""
    avail = _mem_available(meminfo)
    if avail is None:
        return None
    room = _cgroup_room(proc_cgroup, cgroup_root)
    return max(0, avail if room is None else min(avail, room))


def memory_per_rank(comm):
    """The least share of a node's available memory per rank over the nodes of ``comm`` (collective:
    every rank gets the same value), or None where a node's memory cannot be read."""
    from mpi4py import MPI
    node = comm.Split_type(MPI.COMM_TYPE_SHARED)
    try:
        avail = node.bcast(node_available() if node.rank == 0 else None, root=0)
        share = None if avail is None else avail / node.size
    finally:
        node.Free()
    shares = comm.allgather(share)
    return None if any(s is None for s in shares) else min(shares)
