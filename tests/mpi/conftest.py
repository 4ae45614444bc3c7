"""Collective tests: run as ``mpiexec -n 2 python -m pytest tests/mpi`` (./run test does this)."""
import pytest
from mpi4py import MPI


@pytest.fixture
def comm():
    return MPI.COMM_WORLD
