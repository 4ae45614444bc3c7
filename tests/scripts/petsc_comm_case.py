"""Two solves on 2 ranks with a PETSc object on the communicator alive on rank 1 only in between.

Usage: mpiexec -n 2 python tests/scripts/petsc_comm_case.py
Python destroys petsc4py objects at rank-dependent times (garbage collection); PETSc duplicates the
communicator, collectively, whenever the first object on it is created.  Without solver.snes.hold_comm
rank 0 would duplicate again at the second solve and rank 1 would not: a deadlock (the caller's
timeout catches it).  Prints "OK <area1> <area2>" on rank 0.
"""
import math
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

from mpi4py import MPI  # noqa: E402

from vecontact.core.pfft import SlabFFT  # noqa: E402
from vecontact.core.surface import generate  # noqa: E402
from vecontact.physics.modulus import HavriliakNegami  # noqa: E402
from vecontact.physics.spectrum import SelfAffine  # noqa: E402
from vecontact.solver import solve_contact  # noqa: E402
from vecontact.solver.snes import petsc  # noqa: E402


def main():
    comm = MPI.COMM_WORLD
    N, q0 = 32, 2.5e5
    L = 2 * math.pi / q0
    fft = SlabFFT(comm, N)
    h = generate(fft, L, SelfAffine(q0, 2 * q0, N / 16 * q0, 0.8, 1e-28), 7)
    mod = HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10, 0.5)
    first = solve_contact(fft, L, h, mod, 30.0, 3e4, coarse=False)
    v = petsc().Vec().createMPI((4, 4 * comm.size), comm=comm)
    if comm.rank == 0:
        v.destroy()            # rank 1 still holds it, as after a late garbage collection
    second = solve_contact(fft, L, h, mod, 30.0, 3e4, coarse=False)
    v.destroy()
    if comm.rank == 0:
        print("OK", first.area, second.area, first.converged and second.converged, flush=True)


if __name__ == "__main__":
    main()
