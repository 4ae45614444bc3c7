"""The task farm in-process on the launching communicator (``mpiexec -n 2 python -m pytest tests/mpi``).
"""
import os
import shutil
import tempfile
import traceback

import numpy as np
import pytest
import yaml
from mpi4py import MPI

from vecontact import job as jobs
from vecontact.io.results import read_cases
from vecontact.runner import run


@pytest.fixture
def shared_dir(comm):
    d = tempfile.mkdtemp(prefix="vecontact-farm-") if comm.rank == 0 else None
    d = comm.bcast(d, root=0)
    yield d
    comm.Barrier()
    if comm.rank == 0:
        shutil.rmtree(d, ignore_errors=True)


def _job(comm, d, **numerics):
    raw = {
        "output": os.path.join(d, "out.h5"),
        "surface": {"spectrum": "self-affine", "q0": 2.5e5, "qr": 1.0e6, "q1": [2.0e6, 4.0e6], "hurst": 0.8,
                    "C0": 1.0616e-28, "null_band": 4, "seeds": [1]},
        "material": {"model": "havriliak-negami", "E0": 3.0e6, "Einf": 3.0e9, "alpha": 0.5, "beta": 0.5,
                     "tau": 1.0e-10, "nu": 0.5},
        "sweep": {"velocity": [1.0], "pressure": {"area_min": 0.03, "area_max": 0.3, "num": 3}},
        "numerics": dict({"enabled": True}, **numerics),
    }
    path = os.path.join(d, "job.yaml")
    if comm.rank == 0:          # one writer: a rank must never read a half-written job file
        with open(path, "w") as f:
            yaml.safe_dump(raw, f)
    comm.Barrier()
    return jobs.load(path)


def _table(comm, path):
    """The /cases table read on rank 0, on every rank (a read error fails every rank, no hang)."""
    comm.Barrier()
    t, err = None, None
    if comm.rank == 0:
        try:
            t = read_cases(path)
        except Exception:
            err = traceback.format_exc()
    t, err = comm.bcast((t, err), root=0)
    if err:
        pytest.fail("reading the results file on rank 0 failed:\n" + err)
    return t


@pytest.mark.parametrize("rpc", ["auto", 2])
def test_farm_in_process(comm, shared_dir, rpc):
    job = _job(comm, shared_dir, ranks_per_case=rpc)
    assert run(job, comm, quiet=True) == 6
    t = _table(comm, job.output)
    assert len(t) == 6 and set(np.abs(t["status"])) == {1}
    assert set(t["ranks"]) == ({1} if rpc == "auto" else {min(2, comm.size)})
    # a rerun has nothing to do and leaves the table alone
    run(job, comm, quiet=True)
    t2 = _table(comm, job.output)
    np.testing.assert_array_equal(t, t2)


def test_farm_resumes_a_partial_file(comm, shared_dir):
    job = _job(comm, shared_dir)
    run(job, comm, quiet=True)
    full = _table(comm, job.output)
    # drop half the rows as if the job had been killed, then resume
    if comm.rank == 0:
        from vecontact.io.results import ResultsFile
        from vecontact.job import physics_hash, to_yaml
        w = ResultsFile.open(job.output, to_yaml(job), physics_hash(job), comm.size)
        for k in sorted(w.rows)[::2]:
            del w.rows[k]
        w.commit()
    comm.Barrier()
    run(job, comm, quiet=True)
    again = _table(comm, job.output)
    for k in ("q1", "seed", "velocity", "pressure", "N", "status"):
        np.testing.assert_array_equal(full[k], again[k])
    np.testing.assert_allclose(full["area"], again["area"], atol=2.5 / 64 ** 2)
    np.testing.assert_allclose(full["mu"], again["mu"], rtol=1e-5, atol=1e-6)


def test_memory_per_rank_is_one_value(comm):
    """``auto`` by memory: every rank gets the same share (the rule must not differ between ranks),
    here the node's available memory over the ranks on it (one node)."""
    from vecontact.farm.memory import memory_per_rank, node_available
    got = memory_per_rank(comm)
    everyone = comm.allgather(got)
    assert all(v == everyone[0] for v in everyone)      # the same object's value, by contract
    avail = node_available()
    if avail is None:
        assert got is None
    else:
        node = comm.Split_type(MPI.COMM_TYPE_SHARED)
        size = node.size
        node.Free()
        assert got == pytest.approx(avail / size, rel=0.2)
