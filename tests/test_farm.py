"""The MPI task farm (vecontact.farm): scheduling rules, and whole jobs run as subprocesses on
1 and 2 ranks: equivalence, kill -9 and resume, refusals, a fault on one rank, fields.

The jobs are small (N = 64 and 128) and use the real surface generator and solver.
"""
import json
import os
import signal
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest
import yaml

from mpi_util import ROOT, mpiexec

SCRIPTS = os.path.join(ROOT, "tests", "scripts")
sys.path.insert(0, SCRIPTS)

from vecontact.farm import FAULT_ENV, schedule  # noqa: E402
from vecontact.farm.progress import Progress  # noqa: E402
from vecontact.farm.run import petsc_options  # noqa: E402
from vecontact.farm.schedule import Finished, Split, Stop, Work  # noqa: E402
from vecontact.farm.transport import WIDTH, Request, pack, unpack  # noqa: E402
from vecontact.farm.worker import fault_targets  # noqa: E402
from vecontact.cases import Case  # noqa: E402
from vecontact.io.results import CASE_DTYPE, empty_row  # noqa: E402
from vecontact.rows import case_key  # noqa: E402

MAIN = os.path.join(SCRIPTS, "farm_main.py")


# ------------------------------------------------------------------------------------------------
# helpers
def write_job(path, output="out.h5", q1=(2.0e6, 4.0e6), velocity=(0.01, 1.0), seeds=(1,),
              pressure=None, **numerics):
    job = {
        "output": output,
        "surface": {"spectrum": "self-affine", "q0": 2.5e5, "qr": 1.0e6, "q1": list(q1), "hurst": 0.8,
                    "C0": 1.0616e-28, "null_band": 4, "seeds": list(seeds)},
        "material": {"model": "havriliak-negami", "E0": 3.0e6, "Einf": 3.0e9, "alpha": 0.5, "beta": 0.5,
                     "tau": 1.0e-10, "nu": 0.5},
        "sweep": {"velocity": list(velocity),
                  "pressure": pressure or {"area_min": 0.03, "area_max": 0.3, "num": 3}},
        "numerics": dict({"enabled": True, "tolerance": 1e-8}, **numerics),
    }
    with open(path, "w") as f:
        yaml.safe_dump(job, f)
    return str(path)


def env_for(extra=None):
    env = dict(os.environ)
    for k in ("PMI_RANK", "PMI_SIZE", FAULT_ENV):
        env.pop(k, None)
    env["PYTHONPATH"] = ROOT + os.pathsep + env.get("PYTHONPATH", "")
    env.setdefault("OMP_NUM_THREADS", "1")
    env.update(extra or {})
    return env


def command(nranks, args, wrapper=False):
    """`python -m vecontact ARGS`, or with ``wrapper`` tests/scripts/farm_main.py (test-only MPI
    thread level)."""
    args = list(args) + (["--no-plot"] if args and args[0] == "run" else [])   # figures: not tested here
    base = [sys.executable] + ([MAIN] if wrapper else ["-m", "vecontact"]) + args
    return base if nranks == 0 else [mpiexec(), "-n", str(nranks)] + base


def vecontact(nranks, args, cwd, timeout=120, env=None, wrapper=False):
    """Run the CLI (nranks = 0: plain python, no mpiexec); returns the CompletedProcess.

    The run gets its own process group, killed whole on time-out (no orphaned ranks)."""
    cmd = command(nranks, args, wrapper)
    proc = subprocess.Popen(cmd, cwd=cwd, env=env_for(env), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True)
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        raise
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


def cases_of(path):
    with h5py.File(path, "r") as f:
        return f["cases"][()]


def assert_same_results(a, b, N_min=64):
    """Same cases (keys, order) and the same numbers to solver tolerance."""
    assert len(a) == len(b)
    for k in ("q1", "seed", "velocity", "pressure", "theory_area", "theory_mu", "N"):
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    np.testing.assert_array_equal(a["status"], b["status"])
    # area: a count of grid points -- equal, or within a couple of points
    np.testing.assert_allclose(a["area"], b["area"], rtol=0, atol=2.5 / N_min ** 2)
    np.testing.assert_allclose(a["mu"], b["mu"], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(a["mu_geometric"], b["mu_geometric"], rtol=1e-4, atol=1e-6)


# ------------------------------------------------------------------------------------------------
# scheduling rules
def test_ranks_per_case_rule():
    auto = schedule.ranks_for_grid
    assert [auto(N, 4096) for N in (64, 512, 1024, 2048, 4096, 8192)] == [1, 1, 1, 4, 16, 64]
    assert auto(4096, 8) == 8            # never more than the ranks available
    assert auto(8, 100, 16) == 4         # never more than N / 2
    assert auto(512, 100, 3) == 3
    assert schedule.split_factor(16, 4, 2048) == 4
    assert schedule.split_factor(3, 2, 4) == 2   # 3 ranks > N/2: split even though 3 // 2 == 1
    assert schedule.split_factor(5, 16, 4096) == 1


def _cases(q1s=(1e6, 2e6), seeds=(1,), vs=(0.1, 1.0), ps=(1.0, 2.0, 3.0, 4.0)):
    return sorted(Case(q, s, v, p) for q in q1s for s in seeds for v in vs for p in ps)


def test_chains_largest_first_and_rising_pressure():
    cases = _cases()
    N = {1e6: 64, 2e6: 2048}
    todo = np.ones(len(cases), bool)
    todo[[0, 5]] = False
    chains = schedule.build_chains(cases, todo, N.get, 64)
    assert [ch.N for ch in chains] == [2048, 2048, 64, 64]
    assert chains[0].g == 4 and chains[-1].g == 1
    for ch in chains:
        ps = [cases[i].pressure for i in ch.cases]
        assert ps == sorted(ps)
        assert all(todo[i] for i in ch.cases)
    assert sum(len(ch.cases) for ch in chains) == len(cases) - 2


def _simulate(nranks, cases, N, rpc="auto", durations=None, seed=0):
    """Discrete-event run of the Coordinator with groups that split like the real farm: each group
    reports Finished and acts on Work / Split / Stop."""
    rng = np.random.default_rng(seed)
    chains = schedule.build_chains(cases, np.ones(len(cases), bool), N.get, nranks, rpc)
    coord = schedule.Coordinator(chains, cases, writer=None)
    solved, order = [], []
    # event queue: (time, leader, group size, finished)
    events = [(0.0, 0, nranks, None)]
    while events:
        events.sort(key=lambda e: e[0])
        t, leader, gsize, fin = events.pop(0)
        action = coord.request(leader, gsize, fin)
        if isinstance(action, Stop):
            continue
        if isinstance(action, Split):
            for i in range(action.k):
                lo, hi = schedule.split_range(gsize, action.k, i)
                events.append((t, leader + lo, hi - lo, None))
            continue
        assert isinstance(action, Work)
        ch = chains[action.chain]
        idx = ch.cases[action.start]
        assert gsize <= max(1, ch.N // 2)
        order.append((t, ch.N))
        solved.append(idx)
        row = empty_row()
        row["status"], row["seconds"], row["ranks"] = 1, 1.0, gsize
        dt = (durations or {}).get(ch.N, 1.0) * (0.5 + rng.random()) * ch.g / gsize
        events.append((t + dt, leader, gsize, Finished(action.chain, action.start, row)))
    assert coord.active == 0
    return solved, order, coord


@pytest.mark.parametrize("nranks", [1, 2, 3, 7, 64])
def test_coordinator_solves_each_case_once(nranks):
    cases = _cases(q1s=(1e6, 2e6, 4e6), seeds=(1, 2), vs=(0.1, 1.0, 10.0), ps=range(1, 9))
    N = {1e6: 256, 2e6: 1024, 4e6: 2048}
    solved, order, coord = _simulate(nranks, cases, N, durations={256: 0.1, 1024: 1.0, 2048: 5.0})
    assert sorted(solved) == list(range(len(cases)))
    assert coord.nsolved == len(cases)
    # largest first: no 2048 case starts after a smaller one started
    first_small = min(t for t, n in order if n < 2048)
    assert max(t for t, n in order if n == 2048) <= first_small + 1e-12 or nranks >= 8
    if nranks == 64:
        assert coord.steals > 0      # 12 chains of 2048^2 for 16 groups: chains must be split


def test_coordinator_steals_when_idle():
    cases = _cases(q1s=(1e6,), vs=(1.0,), ps=range(1, 9))     # one chain of 8
    solved, _, coord = _simulate(2, cases, {1e6: 64})
    assert sorted(solved) == list(range(8))
    assert coord.steals >= 1


def test_messages_one_chain_on_two_ranks(tmp_path):
    """The coordinator's answers, message by message, for one chain of 8 cases (N = 64, one rank
    per case) on 2 ranks: the farm's group splits, the idle group steals the unstarted half
    [4, 8), a second steal takes [7, 8) from it, and each row reaches the results file once."""
    from vecontact.io.results import ResultsFile, read_cases
    cases = _cases(q1s=(1e6,), vs=(1.0,), ps=range(1, 9))
    chains = schedule.build_chains(cases, np.ones(8, bool), {1e6: 64}.get, 2)
    writer = ResultsFile.open(str(tmp_path / "r.h5"), "", "h", 2)
    coord = schedule.Coordinator(chains, cases, writer)

    def done(pos):
        row = empty_row()
        row["q1"], row["seed"], row["velocity"], row["pressure"] = cases[chains[0].cases[pos]].key
        row["status"], row["seconds"], row["ranks"] = 1, 1.0, 1
        return Finished(0, pos, row, None, {"reason": "converged"})

    script = [((0, 2, None), Split(2)),
              ((0, 1, None), Work(0, 0, 8)),
              ((1, 1, None), Work(0, 4, 8)),              # steal: the unstarted half of [0, 8)
              ((0, 1, done(0)), Work(0, 1, 4)),           # the owner hears of its shorter range
              ((1, 1, done(4)), Work(0, 5, 8)),
              ((0, 1, done(1)), Work(0, 2, 4)),
              ((0, 1, done(2)), Work(0, 3, 4)),
              ((0, 1, done(3)), Work(0, 7, 8)),           # steal again: [5, 8) -> [5, 7) and [7, 8)
              ((1, 1, done(5)), Work(0, 6, 7)),
              ((1, 1, done(6)), Stop()),                  # nothing unstarted is left
              ((0, 1, done(7)), Stop())]
    for (leader, gsize, fin), expected in script:
        action = coord.request(leader, gsize, fin)
        assert action == expected and type(action) is type(expected), (leader, fin, action)
    assert coord.active == 0 and coord.splits == 1 and coord.steals == 2
    assert coord.nsolved == coord.ndone == 8 and coord.nfailed == 0
    assert coord.commit_pending() and not coord.commit_pending()   # nothing new: no second commit
    got = read_cases(writer.path)
    assert [case_key(r) for r in got] == [c.key for c in cases]


@pytest.mark.parametrize("nranks", [3, 64])
def test_messages_on_a_simulated_farm(nranks):
    """Every answer of a simulated farm (_simulate) is a well-formed message: Work within its chain,
    a group's next Work continues at start + 1 inside a range that only shrinks, Split(k >= 2),
    and one Stop per group (1 + the groups the splits added)."""
    cases = _cases(q1s=(1e6, 2e6, 4e6), seeds=(1, 2), vs=(0.1, 1.0, 10.0), ps=range(1, 9))
    N = {1e6: 256, 2e6: 1024, 4e6: 2048}
    _, _, coord = _simulate(nranks, cases, N, durations={256: 0.1, 1024: 1.0, 2048: 5.0})
    last = {}                   # leader -> its last Work
    stops, added = 0, 0
    for leader, action in coord.log:
        assert isinstance(action, (Work, Split, Stop))
        if isinstance(action, Work):
            assert 0 <= action.start < action.stop <= len(coord.chains[action.chain].cases)
            prev = last.get(leader)
            if prev is not None and prev.chain == action.chain and action.start == prev.start + 1:
                assert action.stop <= prev.stop
            last[leader] = action
        elif isinstance(action, Split):
            assert action.k >= 2
            added += action.k - 1
        else:
            stops += 1
    assert stops == 1 + added == 1 + sum(a.k - 1 for _, a in coord.log if isinstance(a, Split))


def test_messages_survive_the_wire():
    """Actions cross to the group as an int64 buffer (pack/unpack), requests as pickles."""
    import pickle
    buf = np.zeros(WIDTH, np.int64)
    for action in (Work(3, 5, 9), Split(4), Stop()):
        pack(action, buf)
        got = unpack(buf)
        assert got == action and type(got) is type(action)
    row = empty_row()
    row["area"] = 0.25
    req = pickle.loads(pickle.dumps(Request(2, Finished(1, 2, row, "x.fields/a.h5", {"reason": "converged"}))))
    assert type(req) is Request and type(req.finished) is Finished and req.size == 2
    assert req.finished[:2] == (1, 2) and req.finished.row["area"] == 0.25
    assert req.finished.link == "x.fields/a.h5" and req.finished.diagnostics == {"reason": "converged"}


def test_fault_targets():
    cases = _cases()
    t = fault_targets(cases, f"1:3, 0:{cases[5].name},junk,2:nosuchcase")
    assert t == {(1, 3), (0, 5)}
    assert fault_targets(cases, "") == set()


def test_progress_line_marks_failures():
    cases = _cases()
    chains = schedule.build_chains(cases, np.ones(len(cases), bool), {1e6: 64, 2e6: 64}.get, 1)
    progress = Progress(cases, chains, nranks=1)
    row = np.zeros((), CASE_DTYPE)
    row["status"], row["residual"], row["N"], row["ranks"] = -1, 3e-4, 64, 1
    line = progress.line(0, row, "max_it")
    assert "NOT CONVERGED" in line and "3.00e-04" in line and f"/{len(cases)}]" in line


# ------------------------------------------------------------------------------------------------
# whole jobs
@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """One serial run of the small job, shared by the comparisons."""
    d = tmp_path_factory.mktemp("farm_ref")
    job = write_job(d / "job.yaml")
    t = time.time()
    p = vecontact(0, ["run", job], cwd=d)
    assert p.returncode == 0, p.stdout + p.stderr
    return d, cases_of(d / "out.h5"), time.time() - t, p.stdout


def test_serial_run(reference):
    d, ref, seconds, out = reference
    assert len(ref) == 12 and (ref["status"] == 1).all()
    assert (ref["ranks"] == 1).all() and set(ref["N"]) == {64, 128}
    assert out.count("] q1=") == 12 and "ETA" in out
    with h5py.File(d / "out.h5", "r") as f:
        assert f.attrs["complete"]
        runs = [json.loads(r) for r in f["runs"][()]]
        diag = [json.loads(r) for r in f["diagnostics"][()]]
    # provenance: one run, every row written by it, its diagnostics agree with the row
    assert len(runs) == 1 and runs[0]["nranks"] == 1 and "petsc_options" in runs[0]
    assert (ref["run"] == 0).all() and len(diag) == len(ref)
    for row, dg in zip(ref, diag):
        assert dg["reason"] == "converged" and dg["method"] == "snes"
        assert dg["levels"][-1]["N"] == row["N"] and dg["levels"][-1]["iterations"] == row["iterations"]
        assert dg["history"][-1][1] == pytest.approx(row["residual"], rel=1e-12)
        assert len(dg["active_set_changes"]) == row["iterations"]
        # the farm's pace probe: a pair on the case's grid, timed after the solve (not in its seconds)
        assert isinstance(dg["raw_pair_seconds"], float) and dg["raw_pair_seconds"] > 0.0


def test_fft_planner_patient_reaches_the_grid_and_keeps_the_results(reference, tmp_path):
    """numerics.fft_planner: the farm plans its SlabFFT (and through it the coarse grids) with it; the
    answers stay those of the default planner to solver tolerance; the stored job names it."""
    _, ref, _, _ = reference
    job = write_job(tmp_path / "job.yaml", fft_planner="patient")
    p = vecontact(0, ["run", job], cwd=tmp_path, env={"XDG_CACHE_HOME": str(tmp_path / "cache")})
    assert p.returncode == 0, p.stdout + p.stderr
    assert_same_results(ref, cases_of(tmp_path / "out.h5"))
    with h5py.File(tmp_path / "out.h5", "r") as f:
        assert yaml.safe_load(f.attrs["job_yaml"])["numerics"]["fft_planner"] == "patient"
    assert list((tmp_path / "cache" / "vecontact").glob("fftw-wisdom-*.pkl"))     # planned here, kept


def test_worker_builds_its_grid_with_the_jobs_planner(monkeypatch, tmp_path):
    from mpi4py import MPI
    import vecontact.core.pfft as pfft
    from vecontact import job as jobs
    from vecontact.farm.worker import Worker
    made = []
    monkeypatch.setattr(pfft, "SlabFFT", lambda comm, N, **kw: made.append((N, kw)) or object())
    for given, want in (({}, "measure"), ({"fft_planner": "patient"}, "patient")):
        job = jobs.load(write_job(tmp_path / "job.yaml", **given))
        Worker(job, MPI.COMM_SELF, None, [], {}, {}, {}, [], {}).fft(MPI.COMM_SELF, 64)
        assert made[-1] == (64, {"threads": 1, "planner": want})


@pytest.mark.parametrize("rpc", [1, 2])
def test_two_ranks_equal_serial(reference, tmp_path, rpc):
    _, ref, _, _ = reference
    job = write_job(tmp_path / "job.yaml", ranks_per_case=rpc)
    p = vecontact(2, ["run", job], cwd=tmp_path)
    assert p.returncode == 0, p.stdout + p.stderr
    got = cases_of(tmp_path / "out.h5")
    assert_same_results(ref, got)
    assert set(got["ranks"]) == {rpc}
    assert "busy fraction per rank: 0:" in p.stdout


def test_dedicated_coordinator_and_three_ranks(reference, tmp_path):
    """Without MPI_THREAD_MULTIPLE rank 0 only coordinates; 3 ranks make 3 groups of 1."""
    _, ref, _, _ = reference
    job = write_job(tmp_path / "job.yaml")
    p = vecontact(2, ["run", job, "-o", "a.h5"], cwd=tmp_path,
                  env={"VECONTACT_TEST_THREAD_LEVEL": "serialized"}, wrapper=True)
    assert p.returncode == 0, p.stdout + p.stderr
    assert "dedicated" in p.stdout
    assert_same_results(ref, cases_of(tmp_path / "a.h5"))
    p = vecontact(3, ["run", job, "-o", "b.h5"], cwd=tmp_path)
    assert p.returncode == 0, p.stdout + p.stderr
    assert_same_results(ref, cases_of(tmp_path / "b.h5"))


def _wait_gone(marker, timeout=30.0):
    """Wait until no process has ``marker`` in its command line (Linux /proc): after a kill -9 of the
    launcher's process group, MPI ranks that the launcher put in a group of their own die a moment
    later, and one may rename its last commit into place before it does."""
    def running():
        for pid in filter(str.isdigit, os.listdir("/proc")):
            try:
                with open(f"/proc/{pid}/cmdline", "rb") as f:
                    if marker.encode() in f.read():
                        return True
            except OSError:             # the process ended while we looked
                pass
        return False

    t0 = time.time()
    while running():
        if time.time() - t0 > timeout:
            raise AssertionError(f"processes of {marker} still running {timeout} s after kill -9")
        time.sleep(0.05)


def test_kill_and_resume(tmp_path):
    """kill -9 mid-sweep (after >= 3 committed cases), resume, compare with an uninterrupted run."""
    kw = dict(q1=(4.0e6,), seeds=(1, 2), pressure={"area_min": 0.02, "area_max": 0.4, "num": 6})
    full = write_job(tmp_path / "full.yaml", output="full.h5", **kw)
    p = vecontact(2, ["run", full, "--quiet"], cwd=tmp_path)
    assert p.returncode == 0, p.stdout + p.stderr
    ref = cases_of(tmp_path / "full.h5")
    assert len(ref) == 24
    job = write_job(tmp_path / "job.yaml", **kw)
    out = tmp_path / "out.h5"
    proc = subprocess.Popen(command(2, ["run", job, "--quiet"]), cwd=tmp_path, env=env_for(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, start_new_session=True)
    n, t0 = 0, time.time()
    try:
        while time.time() - t0 < 60:
            if out.exists():
                try:
                    n = len(cases_of(out))
                except (OSError, KeyError):
                    n = 0
            if n >= 3 or proc.poll() is not None:
                break
            time.sleep(0.005)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
    _wait_gone(str(job))              # a rank outside the launcher's group can finish a commit first
    before = cases_of(out)            # opens after kill -9
    print("killed after", len(before), "of", len(ref))
    assert 3 <= len(before) < len(ref), "the run finished before it could be killed"
    assert (before["status"] == 1).all()
    # the finished cases are intact
    keys = [tuple(r[k] for k in ("q1", "seed", "velocity", "pressure")) for r in ref]
    sel = [keys.index(tuple(r[k] for k in ("q1", "seed", "velocity", "pressure"))) for r in before]
    assert_same_results(ref[sel], before, N_min=128)
    # resume: computes only the missing ones
    p = vecontact(2, ["run", job], cwd=tmp_path)
    assert p.returncode == 0, p.stdout + p.stderr
    assert f"{len(before)} already finished, {len(ref) - len(before)} to solve" in p.stdout
    assert p.stdout.count("] q1=") == len(ref) - len(before)
    final = cases_of(out)
    assert_same_results(ref, final, N_min=128)
    # the rows before the kill keep the first run's index, the rest carry the second's
    done_before = {tuple(r[k] for k in ("q1", "seed", "velocity", "pressure")) for r in before}
    runs_of = [0 if tuple(r[k] for k in ("q1", "seed", "velocity", "pressure")) in done_before else 1
               for r in final]
    assert list(final["run"]) == runs_of
    assert len({tuple(r[k] for k in ("q1", "seed", "velocity", "pressure")) for r in final}) == len(final)
    # and again: nothing left to do
    p = vecontact(0, ["run", job], cwd=tmp_path)
    assert p.returncode == 0 and p.stdout.count("] q1=") == 0 and "0 to solve" in p.stdout


def test_signal_during_a_write_waits_for_it():
    """A signal that interrupts rank 0's own write of the results file ends the job only once the
    file is written (no half-written temporary, the rows of that write kept)."""
    from vecontact.farm.interrupt import Interruptible
    events = []

    class Writer:
        def commit(self, complete=False):
            events.append("write starts")
            handler.handle(signal.SIGINT)          # the signal arrives mid-write
            events.append("write ends")

    class Hub:
        aborting = False

        def abort(self, text, code=1, head="", unwind=True):
            self.aborting = True
            events.append(("abort", code, head, coord.writing))

    coord = schedule.Coordinator([], [], writer=Writer())
    hub = Hub()
    hub.coord = coord
    handler = Interruptible(hub)
    coord.dirty = True
    assert coord.commit_pending()
    assert events == ["write starts", "write ends", ("abort", 130, "interrupted by SIGINT", None)]
    assert coord.after_write is None
    # a second signal (mpiexec forwards the terminal's Ctrl-C to rank 0 too) changes nothing
    events.clear()
    handler.handle(signal.SIGINT)
    assert events == []
    # outside a write the signal acts at once
    hub = Hub()
    hub.coord = coord
    handler = Interruptible(hub)
    handler.handle(signal.SIGTERM)
    assert events == [("abort", 143, "interrupted by SIGTERM", None)]


@pytest.mark.parametrize("nranks, signame, whom", [(2, "SIGINT", "group"), (2, "SIGTERM", "launcher"),
                                                    (0, "SIGINT", "group")])
def test_interrupt_keeps_the_finished_cases(tmp_path, nranks, signame, whom):
    """Ctrl-C (SIGINT to the whole process group, as a terminal sends it) or a scheduler's SIGTERM to
    mpiexec, mid-sweep: one line, exit status 128 + signal, no traceback nor MPI/PETSc messages, the
    finished cases committed; the same command resumes (and removes a temporary file a killed write
    may have left, also when the killed rank was still dying, or a zombie, as the resume opened the file:
    about 1 run in 10 with SIGINT to the whole group; see test_stale_temporaries_removed_live_ones_kept)."""
    kw = dict(q1=(4.0e6,), seeds=(1, 2), pressure={"area_min": 0.02, "area_max": 0.4, "num": 6})
    job = write_job(tmp_path / "job.yaml", **kw)
    out = tmp_path / "out.h5"
    proc = subprocess.Popen(command(nranks, ["run", job, "--quiet"]), cwd=tmp_path, env=env_for(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True)
    n, t0 = 0, time.time()
    try:
        while time.time() - t0 < 60 and proc.poll() is None:
            try:
                n = len(cases_of(out)) if out.exists() else 0
            except (OSError, KeyError):
                n = 0
            if n >= 2:
                break
            time.sleep(0.005)
        sig = getattr(signal, signame)
        if whom == "group":
            os.killpg(proc.pid, sig)
        else:
            proc.send_signal(sig)
        stdout, stderr = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
    assert n >= 2, "the run finished or failed before it could be interrupted:\n" + stdout + stderr
    text = stdout + stderr
    assert proc.returncode == 128 + sig, (proc.returncode, text)
    kept = cases_of(out)
    assert 2 <= len(kept) < 24 and (kept["status"] == 1).all()
    line = (f"vecontact: interrupted by {signame}; {len(kept)} finished cases are kept in the results "
            "file: rerun the same command to resume")
    assert stderr.count(line) == 1, stderr
    for noise in ("Traceback", "PETSC ERROR", "Assertion", "Message truncated", "KeyboardInterrupt"):
        assert noise not in text, text
    p = vecontact(nranks, ["run", job], cwd=tmp_path)
    assert p.returncode == 0, p.stdout + p.stderr
    assert f"{len(kept)} already finished, {24 - len(kept)} to solve" in p.stdout
    assert len(cases_of(out)) == 24
    assert sorted(os.listdir(tmp_path)) == ["job.yaml", "out.h5"]     # no temporary left, even a stale one


def _refused(p):
    assert p.returncode == 2, p.stdout + p.stderr
    lines = p.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("vecontact: error: output:"), p.stderr
    assert "Traceback" not in p.stdout + p.stderr


def test_refusals(reference, tmp_path):
    d, ref, _, _ = reference
    results = str(d / "out.h5")
    # changed physics, same output file
    changed = write_job(tmp_path / "changed.yaml", output=results, velocity=(0.01, 2.0))
    p = vecontact(0, ["run", changed], cwd=tmp_path)
    _refused(p)
    assert "different physics" in p.stderr
    # ... also on 2 ranks: the error reaches every rank, no hang
    p = vecontact(2, ["run", changed], cwd=tmp_path, timeout=60)
    _refused(p)
    # a foreign HDF5 file
    foreign = tmp_path / "foreign.h5"
    with h5py.File(foreign, "w") as f:
        f["x"] = np.arange(3)
    job = write_job(tmp_path / "job.yaml")
    _refused(vecontact(0, ["run", job, "-o", str(foreign)], cwd=tmp_path))
    # a truncated results file
    trunc = tmp_path / "trunc.h5"
    data = open(results, "rb").read()
    with open(trunc, "wb") as f:
        f.write(data[:len(data) // 2])
    p = vecontact(2, ["run", job, "-o", str(trunc)], cwd=tmp_path, timeout=60)
    _refused(p)
    # nothing was touched
    assert len(cases_of(results)) == len(ref)
    assert open(trunc, "rb").read() == data[:len(data) // 2]


def test_fault_on_one_rank_ends_the_job(tmp_path):
    job = write_job(tmp_path / "job.yaml", ranks_per_case=2)
    t = time.time()
    p = vecontact(2, ["run", job], cwd=tmp_path, timeout=60, env={FAULT_ENV: "1:4"})
    assert time.time() - t < 60
    assert p.returncode != 0
    text = p.stdout + p.stderr
    assert text.count("Traceback (most recent call last)") == 1, text
    assert "failed on rank 1" in p.stderr and "injected fault in case 4" in p.stderr
    done = cases_of(tmp_path / "out.h5")       # the file keeps what was finished
    assert 0 < len(done) < 12 and (done["status"] == 1).all()


def test_fault_on_rank0_with_two_groups(tmp_path):
    job = write_job(tmp_path / "job.yaml", ranks_per_case=1)
    p = vecontact(2, ["run", job], cwd=tmp_path, timeout=60, env={FAULT_ENV: "0:0,1:0"})
    assert p.returncode != 0
    assert (p.stdout + p.stderr).count("Traceback (most recent call last)") == 1, p.stdout + p.stderr
    assert "injected fault in case 0" in p.stderr


def test_not_converged_recorded_and_fields(tmp_path):
    job = write_job(tmp_path / "job.yaml", q1=(2.0e6,), velocity=(1.0,), max_iterations=1,
                    fields=["pressure", "gap", "contact"], downsample=2)
    p = vecontact(0, ["run", job], cwd=tmp_path)
    assert p.returncode == 0, p.stdout + p.stderr
    got = cases_of(tmp_path / "out.h5")
    assert (got["status"] == -1).all() and not got["converged"].any()
    with h5py.File(tmp_path / "out.h5", "r") as f:
        reasons = {json.loads(r)["reason"] for r in f["diagnostics"][()]}
    assert reasons == {"diverged_max_it"}, reasons
    assert p.stdout.count("NOT CONVERGED") == len(got)
    assert np.isfinite(got["residual"]).all()
    with h5py.File(tmp_path / "out.h5", "r") as f:
        names = sorted(f["fields"])
        assert len(names) == len(got)
        g = f["fields"][names[0]]
        assert g["pressure"].shape == (32, 32) and g["contact"].dtype == np.uint8
        assert set(g) == {"pressure", "gap", "contact"} and g.attrs["downsample"] == 2


def test_petsc_options_command_line_wins():
    from vecontact.jobtypes import Job, Numerics
    job = Job.from_dict({"numerics": {"petsc": {"snes_type": "newtonls", "ksp_rtol": "0.1"}}})
    got = petsc_options(job, ["-snes_type", "vinewtonrsls", "-snes_monitor"])
    assert got == {"snes_type": "vinewtonrsls", "ksp_rtol": "0.1", "snes_monitor": None}
    assert petsc_options(job, ()) == job.numerics.petsc and isinstance(job.numerics, Numerics)


def test_morphology_columns_are_those_of_the_contact_map(tmp_path):
    """The /cases morphology columns, computed by the group leader from the gathered contact set
    (2 ranks, one group of 2), are the morphology of the stored full-resolution contact field."""
    from vecontact.analysis.morphology import contact_morphology
    job = write_job(tmp_path / "job.yaml", q1=(4.0e6,), velocity=(1.0,), fields=["contact"], ranks_per_case=2)
    p = vecontact(2, ["run", job], cwd=tmp_path)
    assert p.returncode == 0, p.stdout + p.stderr
    got = cases_of(tmp_path / "out.h5")
    assert (got["status"] == 1).all() and (got["ranks"] == 2).all() and (got["patches"] >= 1).all()
    L = 2 * np.pi / 2.5e5
    with h5py.File(tmp_path / "out.h5", "r") as f:
        for row in got:
            name = f"q1_{row['q1']:.6e}_seed_{row['seed']}_v_{row['velocity']:.6e}_p_{row['pressure']:.6e}"
            contact = f["fields"][name]["contact"][()]
            assert contact.shape == (128, 128)
            assert contact.mean() == pytest.approx(row["area"], abs=0.5 / 128 ** 2)
            m = contact_morphology(contact.astype(bool), L / 128)
            assert int(row["patches"]) == m.patches and int(row["percolating"]) == m.percolating
            for k in ("mean_patch_area", "perimeter", "anisotropy_extent", "anisotropy_moments"):
                np.testing.assert_allclose(row[k], getattr(m, k), rtol=1e-12, err_msg=k)


def test_q1_option_solves_a_subset_then_the_rest(reference, tmp_path):
    """``run --q1`` leaves the other q1 to solve; the next run without it completes the same file."""
    _, ref, _, _ = reference
    job = write_job(tmp_path / "job.yaml")
    p = vecontact(0, ["run", job, "--q1", "2e6"], cwd=tmp_path)
    assert p.returncode == 0, p.stdout + p.stderr
    # the lines count to what this run solves, not to the job's 12
    assert "[6/6] q1=2e+06" in p.stdout and "/12]" not in p.stdout, p.stdout
    part = cases_of(tmp_path / "out.h5")
    assert len(part) == 6 and set(part["q1"]) == {2.0e6} and set(part["N"]) == {64}
    with h5py.File(tmp_path / "out.h5", "r") as f:
        assert not f.attrs["complete"]
    p = vecontact(0, ["run", job], cwd=tmp_path)
    assert p.returncode == 0, p.stdout + p.stderr
    assert "6 already finished, 6 to solve" in p.stdout
    assert "[ 7/12] q1=4e+06" in p.stdout and "[12/12] q1=4e+06" in p.stdout, p.stdout
    assert_same_results(ref, cases_of(tmp_path / "out.h5"))
    bad = vecontact(0, ["run", job, "--q1", "3e6"], cwd=tmp_path)
    assert bad.returncode == 2 and bad.stderr.strip().splitlines() == [
        "vecontact: error: --q1: 3e6 is not one of the job's q1 (2e+06, 4e+06)"]
