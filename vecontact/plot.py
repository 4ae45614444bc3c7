"""Figures in the style of Scaraggi & Persson (2015), drawn from a results file only.

- fig1_spectrum.png: C(q) for the q1 set (Fig. 1)
- fig2_friction.png: mu / <(grad h)^2> against A/A0 for each v, one panel per q1 (Fig. 2)
- fig4_area.png: A/A0 against sigma0 / (E0 h'_rms) (Fig. 4)
- fig5_master.png: A/A0 against sigma0 / (E0 xi), the master curve (Fig. 5)
Theory is drawn as lines, converged numerical cases as markers; unconverged cases are never drawn.
"""
import os

import numpy as np

from vecontact.io.results import open_for_reading


def _load(path):
    with open_for_reading(path) as f:
        import yaml
        job = yaml.safe_load(f.attrs["job_yaml"])
        theory = []
        for name in sorted(f["theory"], key=lambda n: f["theory"][n].attrs["q1"]):
            g = f["theory"][name]
            theory.append({"q1": float(g.attrs["q1"]), "slope_rms": float(g.attrs["slope_rms"]),
                           "velocity": g["velocity"][()], "xi": g["xi"][()],
                           "pressure": g["curves/pressure"][()], "area": g["curves/area"][()],
                           "mu": g["curves/mu"][()], "spectrum": (f["spectrum"][name]["q"][()],
                                                                  f["spectrum"][name]["C"][()])})
        cases = f["cases"][()]
        E0 = float(f["theory"].attrs["E0"])
        nu = float(f["theory"].attrs["nu"])
    return job, theory, cases, E0, nu


def drawn_cases(cases):
    """The /cases rows drawn as numerical results: converged ones only (status 1). Rows that did not
    converge (status -1) carry finite numbers for inspection but are never drawn."""
    return cases[cases["status"] == 1]


def _points(done, q1, v):
    return done[(done["q1"] == q1) & (done["velocity"] == v)]


def _colors(n):
    import matplotlib.pyplot as plt
    cmap = plt.get_cmap("viridis")
    return [cmap(x) for x in np.linspace(0.0, 0.85, max(n, 1))]


def plot_results(path, outdir=None):
    """Write the four PNGs; returns their paths."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    job, theory, cases, E0, nu = _load(path)
    outdir = outdir or os.path.splitext(path)[0] + "_figures"
    os.makedirs(outdir, exist_ok=True)
    q0 = job["surface"].get("q0")
    done = drawn_cases(cases)
    velocities = theory[0]["velocity"]
    vcol = dict(zip(velocities, _colors(len(velocities))))
    qcol = _colors(len(theory))
    out = []

    # Fig. 1: spectra
    fig, ax = plt.subplots(figsize=(5, 4))
    for t, c in zip(theory, qcol):
        q, C = t["spectrum"]
        keep = C > 0
        lab = f"q1 = {t['q1'] / q0:.0f} q0" if q0 else f"q1 = {t['q1']:.3g} 1/m"
        ax.loglog(q[keep], C[keep], color=c, label=lab)
    ax.set_xlabel("wavevector q (1/m)")
    ax.set_ylabel("C(q) (m$^4$)")
    ax.legend(fontsize=8)
    ax.set_title("Surface roughness power spectra")
    out.append(_save(fig, outdir, "fig1_spectrum.png"))

    # Fig. 2: mu / <(grad h)^2> vs A/A0, one panel per q1
    fig, axes = plt.subplots(1, len(theory), figsize=(4.2 * len(theory), 3.8), squeeze=False)
    for ax, t in zip(axes[0], theory):
        s2 = t["slope_rms"] ** 2
        for k, v in enumerate(t["velocity"]):
            ax.loglog(t["area"][k], t["mu"][k] / s2, color=vcol[v], label=f"v = {v:g} m/s")
            pts = _points(done, t["q1"], v)
            if len(pts):
                ax.loglog(pts["area"], pts["mu"] / s2, "o", color=vcol[v], ms=4, mfc="none")
        ax.set_xlabel("A/A$_0$")
        ax.set_ylabel(r"$\mu / \langle(\nabla h)^2\rangle$")
        ax.set_title(f"q1 = {t['q1'] / q0:.0f} q0" if q0 else f"q1 = {t['q1']:.3g} 1/m", fontsize=9)
    axes[0][0].legend(fontsize=7)
    fig.suptitle("Friction (lines: theory, circles: exact numerics)", fontsize=10)
    out.append(_save(fig, outdir, "fig2_friction.png"))

    # Fig. 4 and 5: area against scaled pressure
    for fname, scale_name, xlabel in (
            ("fig4_area.png", "slope", r"$\sigma_0 / (E_0\, h'_{\rm rms})$"),
            ("fig5_master.png", "xi", r"$\sigma_0 / (E_0\, \xi)$")):
        fig, ax = plt.subplots(figsize=(5, 4))
        for t, qc in zip(theory, qcol):
            for k, v in enumerate(t["velocity"]):
                scale = E0 * (t["slope_rms"] if scale_name == "slope" else t["xi"][k])
                ax.loglog(t["pressure"][k] / scale, t["area"][k], color=vcol[v], lw=1,
                          label=f"v = {v:g} m/s" if t is theory[0] else None)
                pts = _points(done, t["q1"], v)
                if len(pts):
                    ax.loglog(pts["pressure"] / scale, pts["area"], "o", color=vcol[v], ms=4, mfc="none")
        if scale_name == "xi":
            x = np.geomspace(1e-4, 10, 200)
            from vecontact.physics.theory import erf
            ax.loglog(x, erf(np.sqrt(2.0) * (1 - nu ** 2) * x), "k--", lw=1,
                      label=r"erf($\sqrt{2}(1-\nu^2)x$)")
        ax.set_xlabel(xlabel)
        ax.set_ylabel("A/A$_0$")
        ax.set_ylim(1e-3, 1.05)
        ax.legend(fontsize=7)
        ax.set_title("Contact area" if scale_name == "slope" else "Master curve", fontsize=10)
        out.append(_save(fig, outdir, fname))
    return out


def _save(fig, outdir, name):
    path = os.path.join(outdir, name)
    fig.tight_layout()
    fig.savefig(path, dpi=130)
    import matplotlib.pyplot as plt
    plt.close(fig)
    return path

