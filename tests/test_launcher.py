"""The ./run launcher: -n starts mpiexec, inside an MPI launch it does not start another one."""
import json
import os
import shutil
import subprocess
import sys

import h5py
import numpy as np
import pytest
import yaml

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
RUN = os.path.join(ROOT, "run")


def _run(args, env=None, timeout=300):
    e = dict(os.environ)
    for k in ("PMI_RANK", "PMI_SIZE", "PMIX_RANK", "OMPI_COMM_WORLD_SIZE", "MPI_LOCALRANKID", "SLURM_STEP_ID"):
        e.pop(k, None)
    e.update(env or {})
    return subprocess.run([RUN] + args, capture_output=True, text=True, timeout=timeout, env=e)


def test_info_on_two_ranks():
    proc = _run(["-n", "2", "info"])
    assert proc.returncode == 0, proc.stderr
    assert "ranks: 2" in proc.stdout and "PETSc" in proc.stdout
    assert proc.stdout.count("ranks:") == 1          # printed by rank 0 only


def test_inside_mpi_launch_runs_directly():
    # Pretend to be one rank of an outer launch: ./run must not start mpiexec again.
    proc = _run(["-n", "2", "info"], env={"PMI_RANK": "0", "PMI_SIZE": "1"})
    assert proc.returncode == 0, proc.stderr
    assert "ranks: 1" in proc.stdout


def test_bad_rank_count():
    proc = _run(["-n", "zero", "info"])
    assert proc.returncode != 0 and "-n needs a positive number" in proc.stderr


def test_bad_fftw_choice_stops_before_anything_is_built():
    proc = _run(["info"], env={"VECONTACT_FFTW": "bogus"})
    assert proc.returncode != 0 and proc.stdout == ""
    assert proc.stderr.strip().splitlines() == [
        "run: error: VECONTACT_FFTW must be auto, source or wheel, got 'bogus'"]


def test_surface_command_three_ranks_matches_one(tmp_path):
    job = yaml.safe_load(open(os.path.join(ROOT, "jobs", "demo.yaml")))
    job["surface"].update(q1=[2.0e6], null_band=4, seeds=[3, 4])    # N = 64, uneven on 3 ranks
    path = tmp_path / "job.yaml"
    path.write_text(yaml.safe_dump(job))
    outs = []
    for n in (1, 3):
        out = str(tmp_path / f"s{n}.h5")
        proc = _run(["-n", str(n), "surface", str(path), "-o", out])
        assert proc.returncode == 0, proc.stderr
        outs.append(out)
    with h5py.File(outs[0], "r") as a, h5py.File(outs[1], "r") as b:
        assert sorted(a) == sorted(b) and len(a) == 2
        for name in a:
            assert a[name].shape == (64, 64)
            assert np.array_equal(a[name][()], b[name][()])               # bit for bit: the contract
            # derived statistics are sums whose order depends on the ranks and the numpy build:
            # equal to rounding, a few ulps x log2(N^2) (here 12 x 4 eps, with margin)
            rounding = 4 * np.finfo(float).eps * np.log2(64 * 64)
            np.testing.assert_allclose(a[name].attrs["hrms"], b[name].attrs["hrms"], rtol=rounding, atol=0)
            # random phases: the grid's h_rms equals the lattice sum of the spectrum
            np.testing.assert_allclose(np.sqrt(np.mean(a[name][()] ** 2)), a[name].attrs["hrms"],
                                       rtol=rounding, atol=0)


def test_job_without_ranks_uses_every_core(tmp_path):
    """./run JOB.yaml without -n starts one rank per core the process may run on, whatever
    OMP_NUM_THREADS says (GNU nproc alone would honour it)."""
    job = yaml.safe_load(open(os.path.join(ROOT, "jobs", "demo.yaml")))
    job["surface"].update(q1=[2.0e6], null_band=4)
    job["numerics"] = {"enabled": False}
    job["output"] = str(tmp_path / "out.h5")
    path = tmp_path / "job.yaml"
    path.write_text(yaml.safe_dump(job))
    proc = _run([str(path), "--no-plot"], env={"OMP_NUM_THREADS": "1"})
    assert proc.returncode == 0, proc.stderr
    with h5py.File(tmp_path / "out.h5", "r") as f:
        runs = [json.loads(r) for r in f["runs"][()]]
    assert [r["nranks"] for r in runs] == [len(os.sched_getaffinity(0))]


def test_test_command_runs_every_stage_and_fails_if_any_fails():
    """./run test: the MPI stage runs even when the serial stage fails; the status is non-zero."""
    proc = _run(["test", "-k", "no_test_has_this_name"])
    assert proc.returncode == 1, proc.stderr
    assert "MPI tests on 2 ranks" in proc.stderr
    assert "FAILED: serial tests (exit 5) MPI tests (exit 5)" in proc.stderr   # 5: no tests collected


def _build_fftw(cache, url):
    """Run ./run's build_fftw alone (its text cut from the script), into ``cache``, fetching ``url``."""
    text = open(RUN).read()
    body = text[text.index("\nbuild_fftw() {") + 1:]
    body = body[:body.index("\n}\n") + 3]
    script = "\n".join([
        "set -euo pipefail",
        "die() { printf 'run: error: %s\\n' \"$*\" >&2; exit 1; }",
        "say() { :; }",
        f"PY={sys.executable}; FFTW_CACHE={cache}; FFTW_URL={url}",
        "FFTW_VERSION=3.3.10; FFTW_SHA256=" + "0" * 64 + "; FFTW_SIMD=",
        body,
        "build_fftw",
    ])
    return subprocess.run(["bash", "-c", script], capture_output=True, text=True, timeout=60)


_NO_MAKE = pytest.mark.skipif(shutil.which("make") is None, reason="build_fftw stops earlier without make")


@_NO_MAKE
def test_failed_fftw_fetch_leaves_no_build_folder(tmp_path):
    """A build that cannot fetch FFTW stops with one line naming the URL and the reason, and leaves no
    build folder; it also removes the folders an earlier failed or killed build left (their logs)."""
    stale = tmp_path / "fftw-x.build.AbC123"
    stale.mkdir()
    (stale / "build.log").write_text("an earlier attempt")
    url = (tmp_path / "missing.tar.gz").as_uri()
    proc = _build_fftw(tmp_path / "fftw-x", url)
    assert proc.returncode == 1, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"run: error: could not download {url}: ")
    assert "No such file" in lines[0] and "Traceback" not in proc.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fftw-x.lock"]


@_NO_MAKE
def test_fftw_with_a_wrong_checksum_leaves_no_build_folder(tmp_path):
    """A fetched archive whose sha256 is not FFTW's is refused, and its folder removed."""
    bad = tmp_path / "fftw.tar.gz"
    bad.write_bytes(b"not fftw")
    proc = _build_fftw(tmp_path / "fftw-x", bad.as_uri())
    assert proc.returncode == 1
    assert proc.stderr.strip().splitlines() == [f"run: error: {bad.as_uri()}: wrong sha256"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fftw-x.lock", "fftw.tar.gz"]
