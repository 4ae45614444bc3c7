"""``ranks_per_case: auto`` by memory (vecontact.farm.memory, schedule.ranks_for_grid): the case's
estimate against the measured peaks, the node's available memory from fake /proc and cgroup trees,
and the rule it gives."""
import os
import warnings

import pytest
from mpi4py import MPI

from vecontact.errors import InputWarning
from vecontact.farm import memory, progress, schedule
from vecontact.solver.settings import SolverSettings

GB = 1e9


def test_case_bytes_covers_the_measured_peaks():
    # the largest peak RSS per rank measured at 4096² with the arrays of session 37 (benchmarks/RESULTS.md,
    # "Memory per grid point" and "4096² with the session-39 default"; kB of 1024 bytes): on 1 rank the
    # larger VmHWM of the study's two farm ranks over session 40's 1 and 10 m/s cases (/usr/bin/time
    # gave 7941832 for one 10 m/s, 27 % solve); on 2 the VmHWM of a benchmark worker that solved 27 %
    # and 56 % at 0.01 and 10 m/s (session 38).  The estimate bounds each, within 30 %
    peaks = {1: 7951628 * 1024, 2: 5320328 * 1024}
    for g, peak in peaks.items():
        est = memory.case_bytes(4096, g)
        assert peak <= est <= 1.3 * peak, (g, est)
    # the basis term is the restart rules' largest basis (SolverSettings.restart, inner_restart): the
    # 3 GB budget where it binds (4096^2 on one rank), floored to whole FGMRES iterations
    n = 4096 ** 2
    carry = 4 * n                                          # the map's kernel (float32), within carry_memory / 2
    basis = (memory.case_bytes(4096, 1) - memory.BYTES_PER_POINT * n - carry) / memory.KRYLOV_PEAK
    assert 3e9 - 2 * 8 * 0.3 * n <= basis <= 3e9
    # a small budget: restart_min binds, the free-set GMRES holds 11 whole-grid vectors (1.5 GB), the
    # contact-set steps' inner FGMRES 2 x 11 on up to contact_step_area_small (60 %) of them (1.8 GB)
    small = SolverSettings(restart_memory=1e9, inner_restart_memory=1e9)
    basis = (memory.case_bytes(4096, 1, small) - memory.BYTES_PER_POINT * n - carry) / memory.KRYLOV_PEAK
    assert basis == pytest.approx(8 * 2 * (small.restart_min + 1) * 0.6 * n, rel=1e-12)
    off = SolverSettings(restart_memory=1e9, inner_restart_memory=1e9, contact_step_min_n=8192)
    basis = (memory.case_bytes(4096, 1, off) - memory.BYTES_PER_POINT * n - carry) / memory.KRYLOV_PEAK
    assert basis == pytest.approx(8 * (off.restart_min + 1) * n, rel=1e-12)
    # a small grid: the caps bind, the free-set GMRES's 121 vectors on every point outweigh the inner
    # FGMRES's 2 x 101 on the 30 % of them solved on the contact set; with contact-set steps
    # everywhere the inner FGMRES holds 2 x 101 whole-grid vectors
    n = 256 * 256
    carry = 4 * n
    assert memory.case_bytes(256, 1) == pytest.approx(
        memory.BYTES_PER_POINT * n + memory.KRYLOV_PEAK * 8 * 121 * n + carry, rel=1e-12)
    assert memory.case_bytes(256, 1, SolverSettings(contact_step="contact")) == pytest.approx(
        memory.BYTES_PER_POINT * n + memory.KRYLOV_PEAK * 8 * 202 * n + carry, rel=1e-12)
    # no kernel without the map, without carrying, or where it would not fit within half of carry_memory
    # (8192^2: 268 MB against 150 MB)
    for off in (SolverSettings(carry_map_cost=0.0), SolverSettings(carry_directions=0),
                SolverSettings(carry_memory=8 * n - 1)):
        assert memory.case_bytes(256, 1, off) == pytest.approx(memory.case_bytes(256, 1) - carry, rel=1e-12)
    assert memory.case_bytes(8192, 1) == memory.case_bytes(8192, 1, SolverSettings(carry_map_cost=0.0))
    # 8192^2 on 2 ranks (session 63: 0.01 m/s, 4.5 %, VmHWM of both benchmark workers, kB): the arrays
    # alone are BYTES_PER_POINT to 0.5 % (a 4.5 % case holds few Krylov vectors); the estimate bounds it
    peak, n = 8882352 * 1024, 8192 ** 2 / 2
    assert memory.BYTES_PER_POINT * n == pytest.approx(peak, rel=5e-3)
    assert peak <= memory.case_bytes(8192, 2)
    assert memory.case_bytes(8192, 1, SolverSettings(carry_memory=6e8)) > memory.case_bytes(8192, 1)


def test_auto_by_memory():
    auto = schedule.ranks_for_grid
    # the 2-core development machine: 24.4 GB available when idle, 12.2 GB a rank -> one rank per
    # 4096^2 case; also with 11 GB a rank (two before session 37's smaller arrays), two with 9.5
    assert [auto(N, 2, "auto", 12.2 * GB) for N in (512, 1024, 2048, 4096)] == [1, 1, 1, 1]
    assert auto(4096, 2, "auto", 11 * GB) == 1
    assert auto(4096, 2, "auto", 9.5 * GB) == 2
    # a cluster node with 4 GB a core, and one with 2 GB (the grid rule's choice there)
    assert [auto(N, 4096, "auto", 4 * GB) for N in (1024, 2048, 4096, 8192)] == [1, 2, 8, 32]
    assert [auto(N, 4096, "auto", 2 * GB) for N in (1024, 2048, 4096, 8192)] == [1, 4, 16, 64]
    # every choice fits, and half of it would not
    for mem in (2 * GB, 4 * GB, 8 * GB):
        for N in (2048, 4096, 8192):
            g = auto(N, 4096, "auto", mem)
            assert memory.case_bytes(N, g) <= memory.MEMORY_USE * mem
            assert g == 1 or memory.case_bytes(N, g // 2) > memory.MEMORY_USE * mem
    # capped by the ranks available and N/2; an explicit number ignores the memory
    assert auto(4096, 2, "auto", 1 * GB) == 2
    assert auto(8, 100, "auto", 1e3) == 4
    assert auto(4096, 64, 3, 1 * GB) == 3
    # memory unknown: the grid rule
    assert [auto(N, 4096, "auto", None) for N in (1024, 2048, 4096)] == [1, 4, 16]


def test_auto_fills_the_ranks():
    auto = schedule.ranks_for_grid
    # one 4096^2 case on 2 ranks with room for it on one: both ranks (jobs/paper-maps.yaml)
    assert auto(4096, 2, "auto", 12.2 * GB, count=1) == 2
    assert auto(4096, 2, "auto", 12.2 * GB, count=48) == 1
    # ranks / cases, as a power of two: 12 cases on 64 ranks get 4 each
    assert auto(4096, 64, "auto", 12.2 * GB, count=12) == 4
    # never above the grid rule (1 up to 1024^2, then 1024^2 points a rank), never below memory's g
    assert auto(64, 64, "auto", 12.2 * GB, count=8) == 1
    assert auto(2048, 64, "auto", 12.2 * GB, count=1) == 4
    assert auto(4096, 64, "auto", 3 * GB, count=12) == 16
    # the grid rule and a fixed number ignore the count
    assert auto(4096, 64, "auto", None, count=1) == 16
    assert auto(4096, 64, 2, 12.2 * GB, count=1) == 2


def test_a_grid_that_may_not_fit_is_warned_of():
    from vecontact.farm.run import _warn_memory
    from vecontact.farm.schedule import Chain
    s = SolverSettings()
    # the 2-core development machine, 12.2 GB a rank: 8192^2 needs 14.0 GB a rank on its 2 ranks (by
    # the estimate; 9.1 GB measured at 4.5 % contact), 4096^2 fits on one
    chains = [Chain(0, (1e6, 1, 0.01), [0, 1], 8192, 2), Chain(1, (1e6, 1, 10.0), [2], 8192, 2),
              Chain(2, (5e5, 1, 0.01), [3], 4096, 1)]
    with pytest.warns(InputWarning) as got:
        _warn_memory(chains, 12.2 * GB, s)
    assert [str(w.message) for w in got] == [
        "numerics.ranks_per_case: N=8192 on 2 ranks: a case may need 14.0 GB a rank, more than the 11.0 GB "
        "a rank may fill: it may run out of memory (on more ranks a case needs less a rank)"]
    assert memory.fits(4096, 1, 12.2 * GB) and not memory.fits(8192, 2, 12.2 * GB)
    # silent where everything fits or the memory is unknown
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _warn_memory(chains[2:], 12.2 * GB, s)
        _warn_memory(chains, None, s)
        assert memory.fits(8192, 1, None)


def test_build_chains_passes_memory():
    from vecontact.cases import Case
    cases = [Case(1e6, 1, 1.0, p) for p in (1.0, 2.0)]
    todo = [True, True]
    [ch] = schedule.build_chains(cases, todo, lambda q1: 4096, 2, "auto", 12.2 * GB)
    assert ch.g == 1
    [ch] = schedule.build_chains(cases, todo, lambda q1: 4096, 2, "auto")
    assert ch.g == 2
    # the count is the grid's unfinished cases: with one left, both ranks
    [ch] = schedule.build_chains(cases, [False, True], lambda q1: 4096, 2, "auto", 12.2 * GB)
    assert ch.g == 2
    # counted per grid: one 4096^2 case beside a hundred 512^2 ones on 8 ranks
    mixed = [Case(2e6, 1, 1.0, 1.0)] + [Case(1e6, 1, 1.0, float(p)) for p in range(1, 101)]
    grids = {2e6: 4096, 1e6: 512}
    chains = schedule.build_chains(mixed, [True] * 101, grids.get, 8, "auto", 12.2 * GB)
    assert {(ch.N, ch.g, len(ch.cases)) for ch in chains} == {(4096, 8, 1), (512, 1, 100)}
    # the job's Krylov budgets enter the estimate: 1 GB bases let a 4096^2 case fit on half the ranks
    small = SolverSettings(restart_memory=1e9, inner_restart_memory=1e9)
    [ch] = schedule.build_chains(cases, todo, lambda q1: 4096, 8, "auto", 4 * GB)
    assert ch.g == 8
    [ch] = schedule.build_chains(cases, todo, lambda q1: 4096, 8, "auto", 4 * GB, small)
    assert ch.g == 4


def _write(path, text):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "w") as fh:
        fh.write(text)


def _meminfo(tmp_path, kib):
    p = tmp_path / "meminfo"
    p.write_text(f"MemTotal:       24000000 kB\nMemFree:  1000 kB\nMemAvailable:   {kib} kB\n")
    return str(p)


def test_node_available_cgroup_v2_limit_on_an_ancestor(tmp_path):
    root = str(tmp_path / "cg")
    _write(os.path.join(root, "job", "memory.max"), str(8 * 2 ** 30))
    _write(os.path.join(root, "job", "memory.current"), str(2 ** 30))
    _write(os.path.join(root, "job", "step", "memory.max"), "max")
    _write(os.path.join(root, "job", "step", "memory.current"), "0")
    cg = tmp_path / "self_cgroup"
    cg.write_text("0::/job/step\n")
    got = memory.node_available(_meminfo(tmp_path, 20 * 2 ** 20), str(cg), root)
    assert got == 7 * 2 ** 30                    # the job's 8 GiB less its 1 GiB, under 20 GiB free


def test_node_available_cgroup_v1_and_unlimited(tmp_path):
    root = str(tmp_path / "cg")
    d = os.path.join(root, "memory", "slurm", "job_7")
    _write(os.path.join(d, "memory.limit_in_bytes"), str(6 * 2 ** 30))
    _write(os.path.join(d, "memory.usage_in_bytes"), str(2 ** 30))
    _write(os.path.join(root, "memory", "memory.limit_in_bytes"), "9223372036854771712")
    _write(os.path.join(root, "memory", "memory.usage_in_bytes"), str(10 * 2 ** 30))
    cg = tmp_path / "self_cgroup"
    cg.write_text("5:cpu:/\n4:memory:/slurm/job_7\n0::/\n")
    assert memory.node_available(_meminfo(tmp_path, 20 * 2 ** 20), str(cg), root) == 5 * 2 ** 30
    # no limit anywhere (this machine's kind): MemAvailable
    cg.write_text("4:memory:/\n0::/\n")
    assert memory.node_available(_meminfo(tmp_path, 3 * 2 ** 20), str(cg), root) == 3 * 2 ** 30
    # no cgroup file: MemAvailable; no MemAvailable: unknown
    assert memory.node_available(_meminfo(tmp_path, 2 ** 20), str(tmp_path / "none"), root) == 2 ** 30
    assert memory.node_available(str(tmp_path / "none"), str(cg), root) is None


def test_memory_per_rank_one_rank():
    avail = memory.node_available()
    got = memory.memory_per_rank(MPI.COMM_SELF)
    if avail is None:
        assert got is None
    else:                                        # read twice: the node's memory moves a little
        assert got == pytest.approx(avail, rel=0.2)


def test_start_line_names_the_rule():
    line = progress.start_line(4, 0, 4, 1, 2, "auto", {4096: 1}, True, 11.04e9)
    assert "ranks per case, auto by memory, 11.0 GB a rank: N=4096: 1;" in line
    line = progress.start_line(4, 0, 4, 1, 2, "auto", {4096: 2}, True, None)
    assert "auto by grid, the node's memory unknown: N=4096: 2;" in line
    assert "ranks per case, 2: N=4096: 2;" in progress.start_line(4, 0, 4, 1, 2, 2, {4096: 2}, True)
