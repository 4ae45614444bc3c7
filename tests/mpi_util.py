"""Launch small MPI runs from the serial test-suite (for 1-, 2-, 3-rank comparisons)."""
import os
import shutil
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def mpiexec():
    exe = shutil.which("mpiexec", path=os.path.dirname(sys.executable) + os.pathsep + os.environ.get("PATH", ""))
    if exe is None:
        raise RuntimeError("mpiexec not found next to the Python interpreter or on PATH")
    return exe


def run_mpi(nprocs, args, timeout=300, check=True, env=None, cwd=None):
    """Run ``python ARGS...`` on ``nprocs`` ranks; returns the CompletedProcess (text)."""
    full_env = dict(os.environ)
    full_env.pop("PMI_RANK", None)
    full_env.pop("PMI_SIZE", None)
    full_env["PYTHONPATH"] = ROOT + os.pathsep + full_env.get("PYTHONPATH", "")
    full_env.setdefault("OMP_NUM_THREADS", "1")
    if env:
        full_env.update(env)
    cmd = [mpiexec(), "-n", str(nprocs), sys.executable] + list(args)
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=full_env, cwd=cwd or ROOT)
    if check and proc.returncode != 0:
        raise AssertionError(f"{' '.join(cmd)} failed ({proc.returncode}):\n{proc.stdout}\n{proc.stderr}")
    return proc
