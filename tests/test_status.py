"""``vecontact status``: progress and failures of a sweep, read from its results file alone."""
import os
import subprocess
import sys

import h5py
import numpy as np
import yaml

from vecontact.io.results import ResultsFile, empty_row
from vecontact.status import format_status, read_status

# the stored (resolved) job, the parts status reads: the seeds, and q0, null_band for the grid N = 2 null_band q1 / q0
JOB = {"surface": {"spectrum": "self-affine", "q0": 2.5e5, "q1": [8e6], "null_band": 8, "seeds": [1, 2],
                   "grid": {repr(8e6): 512}}, "numerics": {"enabled": True}}


def _sweep_file(path):
    """2 seeds x 2 velocities x 2 pressures = 8 cases: 2 converged, 1 failed, 5 to solve."""
    w = ResultsFile.open(str(path), yaml.safe_dump(JOB), "h", 2)
    w.set_group("theory", {"q1_0": {"@q1": 8e6, "velocity": np.array([0.01, 10.0]),
                                    "pressure": np.array([[1e4, 2e4], [3e4, 4e4]])}})
    for seed, v, p, status, area in [(1, 0.01, 1e4, 1, 0.011), (1, 0.01, 2e4, 1, 0.023), (2, 10.0, 4e4, -1, 0.05)]:
        r = empty_row()
        r["q1"], r["seed"], r["velocity"], r["pressure"] = 8e6, seed, v, p
        r["status"], r["converged"], r["area"], r["N"], r["ranks"] = status, status == 1, area, 512, 2
        r["seconds"], r["residual"], r["iterations"] = 30.0, 1e-9 if status == 1 else 3.1e-4, 7
        w.add_row(r, diagnostics={"reason": "converged" if status == 1 else "diverged_max_it"})
    w.commit()


def test_status_counts_progress_and_names_failures(tmp_path):
    path = tmp_path / "r.h5"
    _sweep_file(path)
    st = read_status(str(path))
    assert len(st["expected"]) == 8
    lines = format_status("r.h5", st)
    assert lines[0] == "r.h5: 8 cases: 2 converged, 1 NOT converged, 5 to solve"
    table = {tuple(ln.split()[1:3]): ln.split() for ln in lines[2:6]}
    assert table[("1", "0.01")][4:6] == ["2/2", "0"] and table[("1", "0.01")][6] == "0.0110-0.0230"
    assert table[("2", "10")][4:6] == ["0/2", "1"] and table[("2", "10")][6] == "-"
    assert table[("1", "10")][3] == "512"                       # grid from the job when nothing ran
    failed = [ln for ln in lines if ln.startswith("  q1=")]
    assert len(failed) == 1 and "seed=2 v=10 p=4e+04" in failed[0]
    assert "residual 3.10e-04, diverged_max_it, 7 Newton steps" in failed[0]
    run = [ln for ln in lines if ln.startswith("  0: ")]
    assert len(run) == 1 and run[0].endswith("2 ranks on " + st["runs"][0]["host"] + "  3 rows")


def test_status_cli_and_bad_file(tmp_path):
    """status (and plot) refuse a foreign or missing file in one line, exit 2, nothing written."""
    path = tmp_path / "r.h5"
    _sweep_file(path)
    p = subprocess.run([sys.executable, "-m", "vecontact", "status", str(path)], capture_output=True, text=True,
                       timeout=120)
    assert p.returncode == 0 and "1 NOT converged" in p.stdout, p.stderr
    foreign = tmp_path / "x.h5"
    with h5py.File(foreign, "w") as f:
        f["x"] = 1
    for cmd, bad in (("status", foreign), ("status", tmp_path / "missing.h5"), ("plot", foreign)):
        p = subprocess.run([sys.executable, "-m", "vecontact", cmd, str(bad)], capture_output=True,
                           text=True, timeout=120)
        assert p.returncode == 2 and p.stdout == ""
        assert len(p.stderr.strip().splitlines()) == 1 and p.stderr.startswith("vecontact: error: results:")
    assert sorted(q.name for q in tmp_path.iterdir()) == ["r.h5", "x.h5"]     # nothing written


def test_status_into_a_closed_pipe_is_quiet(tmp_path):
    """``vecontact status F | head -1``: the reader is gone before the table is written; exit 141
    (128 + SIGPIPE, as a shell tool), no traceback, buffered or not."""
    path = tmp_path / "r.h5"
    _sweep_file(path)
    code = ("import os, sys; r, w = os.pipe(); os.close(r); os.dup2(w, 1); "
            "from vecontact.cli import main; sys.exit(main(['status', sys.argv[1]]))")
    for unbuffered in ("", "1"):
        env = dict(os.environ, PYTHONUNBUFFERED=unbuffered)
        p = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True,
                           timeout=120, env=env)
        assert p.returncode == 141 and p.stderr == "", (unbuffered, p.returncode, p.stderr)
