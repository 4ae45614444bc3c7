"""Rubber friction against sliding speed for a DMA master curve shifted by WLF to the road
temperature, on a measured spectrum: the velocity sweep, plotted.

    python examples/dma_velocity_sweep.py [--dma FILE] [--psd C.csv] [--temperature T] [--outdir DIR]

The DMA export holds f (Hz), T, E' and E'' (MPa), tan(delta): the columns are picked by name.
"""
import argparse
import os

import numpy as np

import vecontact as vc

HERE = os.path.dirname(os.path.abspath(__file__))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dma", default=os.path.join(HERE, "data", "dma_master_curve.csv"))
    ap.add_argument("--psd", default=os.path.join(HERE, "data", "measured_psd.csv"))
    ap.add_argument("--temperature", type=float, nargs="+", default=[0.0, 20.0, 40.0], help="deg C")
    ap.add_argument("--pressure", type=float, default=0.3e6, help="nominal pressure (Pa)")
    ap.add_argument("--velocities", type=int, default=25, help="points of the sweep")
    ap.add_argument("--outdir", default=".", help="folder for the figure")
    args = ap.parse_args(argv)

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    psd = vc.read_psd(args.psd)
    velocities = np.geomspace(1e-6, 1e2, args.velocities)                  # m/s
    fig, (ax_mu, ax_area) = plt.subplots(1, 2, figsize=(9, 3.8))
    for T in args.temperature:
        E = vc.modulus("table", file=args.dma, frequency_unit="Hz", modulus_unit="MPa",
                       columns=["frequency (Hz)", "E' (MPa)", "E'' (MPa)"],
                       wlf={"C1": 8.86, "C2": 101.6, "T_ref": 20.0, "T": T})
        t = vc.theory(psd, E, velocity=velocities, pressure=args.pressure)
        k = int(np.argmax(t.mu))
        print(f"T = {T:g} C (aT = {E.aT:.3g}): mu peaks at {t.mu[k]:.3f} for v = {velocities[k]:.3g} m/s")
        ax_mu.semilogx(velocities, t.mu, label=f"T = {T:g} C")
        ax_area.loglog(velocities, t.area, label=f"T = {T:g} C")
    ax_mu.set_xlabel("sliding speed v (m/s)")
    ax_mu.set_ylabel("friction coefficient $\\mu$")
    ax_area.set_xlabel("sliding speed v (m/s)")
    ax_area.set_ylabel("A/A$_0$")
    ax_mu.legend(fontsize=8)
    fig.suptitle(f"Persson theory, $\\sigma_0$ = {args.pressure:.3g} Pa", fontsize=10)
    fig.tight_layout()
    os.makedirs(args.outdir, exist_ok=True)
    path = os.path.join(args.outdir, "velocity_sweep.png")
    fig.savefig(path, dpi=120)
    print(path)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
