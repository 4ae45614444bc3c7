"""The examples run (small grids: the example data are small) and say what they should; the two
example jobs run from the command line."""
import os
import subprocess
import sys

import numpy as np
import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLES = os.path.join(ROOT, "examples")
ENV = dict(os.environ, PYTHONPATH=ROOT, OMP_NUM_THREADS="1", MPLBACKEND="Agg")


def run(args, cwd):
    proc = subprocess.run([sys.executable, *args], capture_output=True, text=True, cwd=cwd, env=ENV, timeout=600)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    return proc


def test_theory_on_a_measured_psd(tmp_path):
    out = run([os.path.join(EXAMPLES, "theory_measured_psd.py")], tmp_path).stdout
    assert out.startswith("tabulated PSD: 128 samples")
    areas = [float(line.split("A/A0 = ")[1].split()[0]) for line in out.splitlines() if "A/A0 =" in line]
    assert len(areas) == 15 and all(0 < a < 1 for a in areas)
    assert areas[:5] == sorted(areas[:5])                       # the area grows with the load


def test_exact_solve_of_a_topography_file(tmp_path):
    pytest.importorskip("SurfaceTopography")
    out = run([os.path.join(EXAMPLES, "solve_topography.py")], tmp_path).stdout.splitlines()
    assert "reflected to 96 x 96" in out[0] and out[1].startswith("N = 96")
    rows = np.array([[float(x) for x in line.split()] for line in out[3:]])
    assert rows.shape == (4, 5) and "not converged" not in "".join(out)
    # theory and exact solution: same trend, the same order of magnitude
    assert np.all(np.diff(rows[:, 2]) > 0) and np.all(np.abs(np.log(rows[:, 2] / rows[:, 1])) < 0.5)


def test_velocity_sweep_for_a_dma_table_with_wlf(tmp_path):
    proc = run([os.path.join(EXAMPLES, "dma_velocity_sweep.py"), "--outdir", str(tmp_path), "--velocities", "13"],
               tmp_path)
    lines = proc.stdout.splitlines()
    assert [line.split()[2] for line in lines[:3]] == ["0", "20", "40"]
    peaks = [float(line.split("v = ")[1].split()[0]) for line in lines[:3]]
    assert peaks[0] < peaks[1] < peaks[2]                         # warmer rubber: the peak moves to higher v
    assert os.path.getsize(tmp_path / "velocity_sweep.png") > 0
    assert "InputWarning" in proc.stderr                          # the table does not cover every q v


@pytest.mark.parametrize("job", ["psd_job.yaml", "topography_job.yaml"])
def test_example_jobs_from_the_command_line(tmp_path, job):
    if job == "topography_job.yaml":
        pytest.importorskip("SurfaceTopography")
    out = tmp_path / "results.h5"
    run(["-m", "vecontact", "run", os.path.join(EXAMPLES, job), "-o", str(out), "--quiet", "--no-plot"], tmp_path)
    from vecontact.io.results import read_cases
    cases = read_cases(str(out))
    assert len(cases) == 4 if job == "psd_job.yaml" else 2
    assert np.all(cases["status"] == 1)
