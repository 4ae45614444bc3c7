"""Results file: layout, provenance, atomic commits and refusals; theory-only jobs end to end."""
import json
import os
import subprocess
import sys

import h5py
import numpy as np
import pytest
import yaml

from vecontact.errors import ResultsFileError
from vecontact.io.results import CASE_DTYPE, ResultsFile, empty_row, read_cases

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _row(q1, seed, v, p, area):
    r = empty_row()
    r["q1"], r["seed"], r["velocity"], r["pressure"], r["theory_area"] = q1, seed, v, p, area
    return r


def test_commit_is_atomic_and_sorted(tmp_path):
    path = str(tmp_path / "r.h5")
    w = ResultsFile.open(path, "job: 1\n", "hash-a", 2)
    w.add_row(_row(2.0, 1, 1.0, 5.0, 0.2))
    w.add_row(_row(1.0, 1, 1.0, 5.0, 0.1))
    w.commit()
    assert [n for n in os.listdir(tmp_path)] == ["r.h5"]          # no temporary left behind
    t = read_cases(path)
    assert list(t["q1"]) == [1.0, 2.0] and list(t["theory_area"]) == [0.1, 0.2]
    with h5py.File(path, "r") as f:
        assert f.attrs["physics_hash"] == "hash-a" and f.attrs["nranks"] == 2
        assert f.attrs["job_yaml"] == "job: 1\n" and not f.attrs["complete"]
        units = json.loads(f["cases"].attrs["units"])
        assert units["pressure"] == "Pa" and units["velocity"] == "m/s" and units["q1"] == "1/m"
    # reopen for a restart: finished rows come back; a rewritten row does not duplicate
    w2 = ResultsFile.open(path, "job: 1\n", "hash-a", 1)
    assert w2.done() == {(1.0, 1, 1.0, 5.0), (2.0, 1, 1.0, 5.0)}
    w2.add_row(_row(1.0, 1, 1.0, 5.0, 0.1))
    w2.commit(complete=True)
    assert len(read_cases(path)) == 2


def test_reserved_columns_present():
    for name in ("q1", "seed", "velocity", "pressure", "theory_area", "theory_mu", "xi", "area", "mu",
                 "mu_geometric", "mean_gap", "converged", "iterations", "fft_pairs", "residual", "seconds"):
        assert name in CASE_DTYPE.names


def test_refusals(tmp_path):
    path = str(tmp_path / "r.h5")
    w = ResultsFile.open(path, "", "hash-a", 1)
    w.commit()
    with pytest.raises(ResultsFileError, match="different physics"):
        ResultsFile.open(path, "", "hash-b", 1)
    foreign = str(tmp_path / "foreign.h5")
    with h5py.File(foreign, "w") as f:
        f["x"] = np.arange(3)
    with pytest.raises(ResultsFileError, match="not a vecontact results file"):
        ResultsFile.open(foreign, "", "hash-a", 1)
    truncated = str(tmp_path / "trunc.h5")
    with open(path, "rb") as src, open(truncated, "wb") as dst:
        dst.write(src.read()[:700])
    with pytest.raises(ResultsFileError, match="cannot be read"):
        ResultsFile.open(truncated, "", "hash-a", 1)
    # nothing was overwritten
    with h5py.File(foreign, "r") as f:
        assert list(f) == ["x"]


def _theory_job(tmp_path, **numerics):
    job = yaml.safe_load(open(os.path.join(ROOT, "jobs", "demo.yaml")))
    job["output"] = str(tmp_path / "demo.h5")
    job["numerics"] = {"enabled": False, **numerics}
    path = tmp_path / "job.yaml"
    path.write_text(yaml.safe_dump(job))
    return str(path), job["output"]


def test_theory_job_end_to_end_and_plot(tmp_path):
    path, out = _theory_job(tmp_path)
    proc = subprocess.run([sys.executable, "-m", "vecontact", "run", path, "--quiet"],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert sorted(os.listdir(tmp_path / "demo_figures"))[0] == "fig1_spectrum.png"   # run draws them
    with h5py.File(out, "r") as f:
        cases = f["cases"][()]
        assert f.attrs["complete"] and f.attrs["format"] == "vecontact-results/1"
        assert f.attrs["vecontact_version"] and f.attrs["git_commit"] and f.attrs["created"]
        job = yaml.safe_load(f.attrs["job_yaml"])
        assert job["sweep"]["velocity"] == [0.01, 1.0, 10.0]
        g = f["theory/q1_0"]
        assert g["P_q"].shape == (3, 4, g["q"].shape[0])
        # P(q) decreases from 1 at q0 to the contact area at q1
        P = g["P_q"][()]
        assert np.all(np.diff(P, axis=-1) <= 1e-12)
        assert np.allclose(P[..., -1], g["area"][()], rtol=1e-12)
    assert len(cases) == 2 * 3 * 4                      # q1 x v x p
    assert np.all(cases["status"] == 0) and np.all(np.isnan(cases["area"]))
    # pressures were chosen so the theory spans the requested area range
    for q1 in np.unique(cases["q1"]):
        for v in np.unique(cases["velocity"]):
            a = cases["theory_area"][(cases["q1"] == q1) & (cases["velocity"] == v)]
            assert a.min() == pytest.approx(0.02, rel=1e-4) and a.max() == pytest.approx(0.4, rel=1e-4)
    proc = subprocess.run([sys.executable, "-m", "vecontact", "plot", out, "-o", str(tmp_path / "fig")],
                          capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert "fig 3 (contact maps) skipped" in proc.stdout                # no --maps
    for name in ("fig1_spectrum.png", "fig2_friction.png", "fig4_area.png", "fig5_master.png",
                 "theory_error.png", "morphology.png", "morphology_vs_v.png", "gamma_sensitivity.png"):
        p = tmp_path / "fig" / name
        assert p.stat().st_size > 10000
        assert open(p, "rb").read(8) == b"\x89PNG\r\n\x1a\n"


def test_info_prints_stack():
    proc = subprocess.run([sys.executable, "-m", "vecontact", "info"], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    for word in ("python", "numpy", "mpi4py", "MPI library", "PETSc", "FFTW", "ranks: 1"):
        assert word in proc.stdout


def test_runs_log_and_diagnostics_survive_restarts(tmp_path):
    path = str(tmp_path / "r.h5")
    w = ResultsFile.open(path, "", "hash-a", 2)
    w.note_run(petsc_options={"ksp_type": "bcgs"})
    w.add_row(_row(2.0, 1, 1.0, 5.0, 0.2), diagnostics={"reason": "converged", "its": np.int64(7)})
    w.add_row(_row(1.0, 1, 1.0, 5.0, 0.1))                      # theory-only row: no diagnostics
    w.commit()
    w2 = ResultsFile.open(path, "", "hash-a", 1)               # restart: a second run
    w2.add_row(_row(3.0, 1, 1.0, 5.0, 0.3), diagnostics={"reason": "diverged_max_it"})
    w2.commit()
    with h5py.File(path, "r") as f:
        runs = [json.loads(s) for s in f["runs"][()]]
        cases = f["cases"][()]
        diag = [s.decode() for s in f["diagnostics"][()]]
    assert [r["run"] for r in runs] == [0, 1] and [r["nranks"] for r in runs] == [2, 1]
    assert runs[0]["petsc_options"] == {"ksp_type": "bcgs"} and "petsc_options" not in runs[1]
    assert runs[0]["git_commit"] and runs[0]["versions"]["numpy"] == np.__version__
    assert list(cases["q1"]) == [1.0, 2.0, 3.0] and list(cases["run"]) == [0, 0, 1]
    # /diagnostics is aligned with the sorted /cases rows
    assert diag[0] == "" and json.loads(diag[1]) == {"reason": "converged", "its": 7}
    assert json.loads(diag[2])["reason"] == "diverged_max_it"


def test_file_without_runs_log_resumes(tmp_path):
    """A file written before the run column, /runs and /diagnostics existed stays readable and
    resumable; its rows keep run = -1 (unknown)."""
    path = str(tmp_path / "old.h5")
    old_dtype = np.dtype([(n, CASE_DTYPE[n]) for n in CASE_DTYPE.names if n != "run"])
    row = np.zeros(1, old_dtype)
    row["q1"], row["seed"], row["velocity"], row["pressure"], row["area"] = 1.0, 1, 1.0, 5.0, 0.25
    with h5py.File(path, "w") as f:
        f.attrs["format"], f.attrs["physics_hash"] = "vecontact-results/1", "hash-a"
        f["cases"] = row
    w = ResultsFile.open(path, "", "hash-a", 1)
    w.add_row(_row(2.0, 1, 1.0, 5.0, 0.2))
    w.commit()
    t = read_cases(path)
    assert list(t["run"]) == [-1, 0] and t["area"][0] == 0.25
    with h5py.File(path, "r") as f:
        assert len(f["runs"]) == 1 and len(f["diagnostics"]) == 2


def test_git_commit_flags_uncommitted_changes(tmp_path):
    from vecontact.io.results import git_commit

    def git(*args):
        subprocess.run(["git", "-c", "user.name=t", "-c", "user.email=t@t", *args], cwd=tmp_path,
                       check=True, capture_output=True)
    git("init", "-q")
    code = tmp_path / "pkg"
    code.mkdir()
    (code / "a.py").write_text("x = 1\n")
    (tmp_path / "results.h5").write_text("rows\n")
    git("add", "pkg/a.py", "results.h5")
    git("commit", "-qm", "a")
    clean = git_commit(str(code))
    assert len(clean) == 40 and all(c in "0123456789abcdef" for c in clean)
    (code / "untracked.txt").write_text("not code\n")          # untracked files do not count
    assert git_commit(str(code)) == clean
    # a tracked file outside the code (a results file committed as a sweep grows) does not count
    (tmp_path / "results.h5").write_text("more rows\n")
    assert git_commit(str(code)) == clean
    assert git_commit(str(tmp_path)) == clean + "+dirty"
    (code / "a.py").write_text("x = 2\n")
    assert git_commit(str(code)) == clean + "+dirty"


def test_unconverged_cases_are_never_drawn():
    """plot draws /cases rows with status 1 only; a failed row (-1) keeps its finite numbers in the
    file for inspection but is not a result, and theory-only rows (0) have none."""
    from vecontact.plot import drawn_cases
    rows = []
    for status, area in ((1, 0.25), (-1, 0.5), (0, np.nan), (1, 0.125)):
        r = _row(1e7, 1, 1.0, 1e5 * (len(rows) + 1), 0.3)
        r["status"], r["area"], r["mu"] = status, area, 0.01 * area
        rows.append(r)
    cases = np.stack(rows)
    got = drawn_cases(cases)
    assert got["area"].tolist() == [0.25, 0.125] and (got["status"] == 1).all()
    assert got["pressure"].tolist() == [1e5, 4e5]
    assert len(drawn_cases(cases[:0])) == 0


def test_stale_temporaries_removed_live_ones_kept(tmp_path):
    """A writer killed mid-write leaves <output>.tmp-<pid>: the next open removes it, unless a live
    process has that pid.  A zombie (exited, not yet reaped: a rank mpiexec has just killed) is not
    live: its file goes too (the resume after a Ctrl-C kept one, about 1 run in 10)."""
    import subprocess
    import sys
    import time
    from vecontact.io.results import remove_stale_temporaries
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True).stdout.strip()
    zombie = subprocess.Popen([sys.executable, "-c", "pass"])      # not waited for: a zombie once it exits
    try:
        t0 = time.time()
        while open(f"/proc/{zombie.pid}/stat").read().rsplit(")", 1)[1].split()[0] != "Z":
            assert time.time() - t0 < 30, "the child did not exit"
            time.sleep(0.01)
        out = tmp_path / "out.h5"
        for name in (f"out.h5.tmp-{dead}", f"out.h5.tmp-{zombie.pid}", f"out.h5.tmp-{os.getppid()}",
                     "out.h5.tmp-x", "other.h5.tmp-1"):
            (tmp_path / name).write_bytes(b"partial")
        remove_stale_temporaries(str(out))
    finally:
        zombie.wait()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(
        [f"out.h5.tmp-{os.getppid()}", "out.h5.tmp-x", "other.h5.tmp-1"])
