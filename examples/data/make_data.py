"""Make the example data files (run once; the outputs are committed next to this script).

They stand in for measurements (no measured data of the paper's compound is published):

* ``measured_psd.csv``: the radially averaged C(q) of a 256 x 256 surface with Gaussian random
  amplitudes (so it is as noisy as a measured spectrum) drawn from a self-affine spectrum with
  roll-off: L = 50 um, qr = 4 q0, q1 = 64 q0, H = 0.8, h_rms = 0.3 um;
* ``dma_master_curve.csv``: a DMA master curve at T_ref = 20 C, f in Hz, E' and E'' in MPa,
  sampled from the reference Havriliak-Negami compound of docs/conventions.md (E0 = 3 MPa,
  Einf = 3 GPa, alpha = beta = 0.5, tau = 1e-10 s), with a temperature column and tan(delta)
  as a DMA export has them;
* ``scan.x3p``: a 64 x 48 optical-profilometer-like scan in X3P (heights in float32, 0.39 um
  pixels), from the same kind of surface, tilted by 0.2 % and offset by 5 um (written by
  SurfaceTopography's X3P writer).
"""
import os

import numpy as np
from mpi4py import MPI

from vecontact.core.pfft import SlabFFT
from vecontact.core.surface import generate
from vecontact.physics.modulus import HavriliakNegami
from vecontact.physics.spectrum import SelfAffine, Tabulated

HERE = os.path.dirname(os.path.abspath(__file__))


def measured_psd():
    L = 50e-6
    q0 = 2 * np.pi / L
    spectrum = SelfAffine.from_hrms(q0, 4 * q0, 64 * q0, 0.8, 0.3e-6)
    fft = SlabFFT(MPI.COMM_SELF, 256)
    h = generate(fft, L, spectrum, seed=7, amplitudes="gaussian")
    psd = Tabulated.from_surface(fft, h, L)
    with open(os.path.join(HERE, "measured_psd.csv"), "w") as f:
        f.write("# radially averaged PSD of a 50 um scan (synthetic stand-in, see make_data.py)\n")
        f.write("q (1/m),C (m^4)\n")
        for q, C in zip(psd.q, psd.C):
            f.write(f"{q:.6e},{C:.6e}\n")


def dma_master_curve():
    E = HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10)
    f = np.geomspace(1e-3, 1e10, 40)
    e = E(2 * np.pi * f)
    with open(os.path.join(HERE, "dma_master_curve.csv"), "w") as out:
        out.write("# master curve at T_ref = 20 C (synthetic stand-in, see make_data.py)\n")
        out.write("frequency (Hz),temperature (C),E' (MPa),E'' (MPa),tan delta\n")
        for fi, ei in zip(f, e):
            out.write(f"{fi:.6e},20,{ei.real / 1e6:.6e},{ei.imag / 1e6:.6e},{ei.imag / ei.real:.6e}\n")


def scan():
    from SurfaceTopography import Topography
    L = 25e-6
    q0 = 2 * np.pi / L
    spectrum = SelfAffine.from_hrms(q0, 4 * q0, 16 * q0, 0.8, 25e-9)
    h = generate(SlabFFT(MPI.COMM_SELF, 64), L, spectrum, seed=3)[:, :48]
    dx = L / 64
    x = np.arange(64)[:, None] * dx
    h = h + 2e-3 * x + 5e-6
    Topography(h * 1e6, (64 * dx * 1e6, 48 * dx * 1e6), unit="um").to_x3p(os.path.join(HERE, "scan.x3p"),
                                                                           dtype="F")


if __name__ == "__main__":
    measured_psd()
    dma_master_curve()
    scan()
