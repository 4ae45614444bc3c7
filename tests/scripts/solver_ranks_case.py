"""Solve one rough viscoelastic contact on however many ranks this is launched with; rank 0 prints JSON.

Usage: python tests/scripts/solver_ranks_case.py N METHOD [MODEL]
The heights are made with vecontact.core.surface.generate (which must give the same surface bit for
bit on any number of ranks: its gathered checksum is printed too) and the solution scalars plus
checksums of the gathered fields are printed for comparison across rank counts.
"""
import hashlib
import json
import math
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), ".."))

import numpy as np  # noqa: E402
from mpi4py import MPI  # noqa: E402

from vecontact.core.pfft import SlabFFT  # noqa: E402
from vecontact.core.surface import generate  # noqa: E402
from vecontact.physics.modulus import Elastic, HavriliakNegami  # noqa: E402
from vecontact.physics.spectrum import SelfAffine  # noqa: E402
from vecontact.solver import solve_contact  # noqa: E402


def main():
    N = int(sys.argv[1])
    method = sys.argv[2]
    model = sys.argv[3] if len(sys.argv) > 3 else "hn"
    comm = MPI.COMM_WORLD
    q0 = 2.5e5
    L = 2 * math.pi / q0
    psd = SelfAffine(q0, 2 * q0, N / 16 * q0, 0.8, 1e-28)
    fft = SlabFFT(comm, N)
    h = generate(fft, L, psd, 7)
    if model == "elastic":
        mod, v, sigma0 = Elastic(3e6, 0.5), 0.0, 4e3
    else:
        mod, v, sigma0 = HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10, 0.5), 30.0, 3e4
    res = solve_contact(fft, L, h, mod, v, sigma0, method=method)
    hf = fft.gather(np.ascontiguousarray(h))
    pf = fft.gather(np.ascontiguousarray(res.pressure))
    gf = fft.gather(np.ascontiguousarray(res.gap))
    if comm.rank == 0:
        out = dict(
            nprocs=comm.size, N=N, rows=[int(fft.row_start), int(fft.row_stop)],
            area=res.area, mu=res.mu, mu_geometric=res.mu_geometric, mean_gap=res.mean_gap,
            rigid_position=res.rigid_position, converged=bool(res.converged), iterations=int(res.iterations),
            residual=float(res.residual),
            h_sha=hashlib.sha1(np.ascontiguousarray(hf, dtype="<f8").tobytes()).hexdigest(),
            hrms=float(np.std(hf)),
            pressure=pf.tolist() if N <= 96 else None,
            gap=gf.tolist() if N <= 96 else None,
            p_max=float(pf.max()), p_sum=float(pf.sum()),
        )
        print("RESULT " + json.dumps(out))
    # every rank must report the same scalars (collective reductions)
    scalars = np.array([res.area, res.mu, res.mu_geometric, res.mean_gap, float(res.converged)])
    allsc = comm.allgather(scalars)
    if comm.rank == 0:
        spread = float(np.max(np.abs(np.array(allsc) - scalars)))
        print("SPREAD " + json.dumps({"spread": spread}))


if __name__ == "__main__":
    main()
