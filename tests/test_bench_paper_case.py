"""benchmarks/paper_case.py: the benchmarks solve the study's surfaces (jobs/paper.yaml), bit for bit."""
import numpy as np
import pytest
from mpi4py import MPI

from reference.bench import load
from vecontact import api as vc
from vecontact.core.pfft import SlabFFT
from vecontact.physics.modulus import make_modulus


@pytest.fixture(scope="module")
def case():
    return load("paper_case")


def test_every_benchmark_size_is_a_study_grid(case):
    """N = 512 ... 4096 (benchmarks/solver.py's sizes) are the grids of the job's four q1 (32 ... 256 q0)."""
    s = case.job().surface
    for N, k in ((512, 32), (1024, 64), (2048, 128), (4096, 256)):
        q1 = case.q1_of(N)
        assert q1 == pytest.approx(k * s.q0, rel=1e-12)
        assert any(abs(q1 - x) <= 1e-9 * x for x in s.q1)
        assert s.grid(q1) == N


def test_surface_and_compound_are_the_jobs(case):
    """The 512^2 surface of seed 2 is vc.surface's for the job's (q1, seed) to the bit; the compound is
    the job's material, and the elastic limit its E0 and nu."""
    fft = SlabFFT(MPI.COMM_SELF, 512, planner="estimate")
    h = case.surface(fft, 2)
    assert np.array_equal(h, vc.surface(case.JOB_FILE, case.q1_of(512), 2).heights)
    assert case.period() == pytest.approx(2 * np.pi / 2.5e5, rel=1e-15)
    omega = np.geomspace(1e-2, 1e12, 29)
    job_material = make_modulus({"model": "havriliak-negami", "E0": 3e6, "Einf": 3e9, "alpha": 0.5,
                                 "beta": 0.5, "tau": 1e-10, "nu": 0.5})
    assert np.array_equal(case.compound()(omega), job_material(omega))
    el = case.elastic()
    assert (el.E0, el.nu) == (3e6, 0.5)
