"""Figures of Scaraggi & Persson (2015) and past it, drawn from a results file only.

``vecontact plot RESULTS.h5 [--maps MAPS.h5] [-o DIR]`` writes:

- fig1_spectrum.png: C(q) for the q1 set (Fig. 1)
- fig2_friction.png: mu / <(grad h)^2> against A/A0 for each v, (a) the large system (largest q1 with
  results), (b) the small one (smallest q1) (Fig. 2)
- fig3_contact_maps.png: contact maps at v = 10 m/s, A/A0 ~ 0.05, with an enlarged patch (Fig. 3; only
  with ``--maps``, see :mod:`vecontact.plot_maps`)
- fig4_area.png: A/A0 against sigma0 / (E0 h'_rms) for every q1 at v = 1 and 10 m/s (Fig. 4)
- fig5_master.png: A/A0 against sigma0 / (E0 xi(v)) for all q1 and v, the master curve (Fig. 5)
- theory_error.png, morphology.png, morphology_vs_v.png, gamma_sensitivity.png: past the paper
  (:mod:`vecontact.plot_beyond`)

Theory is drawn as lines, numerics as seed means with standard-error bars (vecontact.analysis.ensemble);
unconverged cases are never drawn or averaged. Each figure's footnote says how many seeds each q1 has
and which q1 have no results yet.
"""
import os

import numpy as np

from vecontact import plot_beyond, plot_maps
from vecontact.analysis.curves import enough_abscissas, erf_small_load_slope, fit_master_curve, master_curve
from vecontact.analysis.ensemble import converged_rows, select
from vecontact.analysis.paper import abscissa, collapse, master_slope
from vecontact.analysis.study import load_study
from vecontact.physics.theory import erf
from vecontact.plot_style import (LINESTYLES, draw_points, friction_panel, marker_handles, markers, palette,
                                  pyplot, save, seeds_note, velocity_handles)

#: Velocities of Fig. 4 (the paper's); when the study has not both, its two fastest.
FIG4_VELOCITIES = (1.0, 10.0)
MAPS_SKIPPED = "fig 3 (contact maps) skipped: no --maps file given"


def drawn_cases(cases):
    """The /cases rows drawn as numerical results: converged ones only (status 1). Rows that did not
    converge (status -1) carry finite numbers for inspection but are never drawn."""
    return converged_rows(cases)


def plot_results(path, outdir=None, maps=None):
    """Write every figure (fig 3 only with ``maps``, a maps results file); returns their paths."""
    study = load_study(path)
    outdir = outdir or os.path.splitext(path)[0] + "_figures"
    os.makedirs(outdir, exist_ok=True)
    out = [spectrum_figure(study, outdir), friction_figure(study, outdir)]
    if maps is not None:
        out.append(plot_maps.maps_figure(load_study(maps), outdir))
    out += [area_figure(study, outdir), master_figure(study, outdir)]
    out += plot_beyond.figures(study, outdir)
    return out


def spectrum_figure(study, outdir):
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(5, 4))
    colors = palette(study.q1s)
    for th in study.theories:
        c = colors[th.q1]
        keep = th.spectrum_C > 0
        ax.loglog(th.spectrum_q[keep], th.spectrum_C[keep], color=c, label=f"q1 = {study.q1_label(th.q1)}")
    ax.set_xlabel("wavevector q (1/m)")
    ax.set_ylabel("C(q) (m$^4$)")
    ax.legend(fontsize=8)
    ax.set_title("Fig. 1: surface roughness power spectra", fontsize=10)
    return save(fig, outdir, "fig1_spectrum.png")


def friction_figure(study, outdir):
    plt = pyplot()
    have = study.q1_with_results()
    small = min(study.q1s)
    large = max(have) if have and max(have) > small else max(study.q1s)
    colors = palette(study.velocities)
    titles = [f"(a) large system: q1 = {study.q1_label(large)}", f"(b) small system: q1 = {study.q1_label(small)}"]
    if large in have and large != max(study.q1s):
        titles[0] += f"\n(largest q1 with results; {study.q1_label(max(study.q1s))} not yet)"
    fig, axes = plt.subplots(1, 2, figsize=(9, 4))
    for k, (ax, q1) in enumerate(zip(axes, (large, small))):
        friction_panel(ax, study, q1, colors)
        ax.set_title(titles[k] + ("" if q1 in have else "\n(theory only: no converged cases yet)"), fontsize=9)
    axes[0].legend(handles=velocity_handles(colors), fontsize=7)
    fig.suptitle("Fig. 2: friction (lines: theory, points: exact numerics)", fontsize=10)
    return save(fig, outdir, "fig2_friction.png", seeds_note(study, study.points(), [large, small]))


def fig4_velocities(study):
    vs = [v for v in FIG4_VELOCITIES if v in study.velocities]
    return vs if len(vs) == len(FIG4_VELOCITIES) else sorted(study.velocities)[-2:]


def area_figure(study, outdir):
    """Fig. 4: A/A0 against sigma0 / (E0 h'_rms), colour per q1, line style and marker per v."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(5.5, 4.5))
    qcol = palette(study.q1s, "plasma")
    vs = fig4_velocities(study)
    for i, v in enumerate(vs):
        for q1, c in qcol.items():
            th = study.theory(q1)
            k = th.v_index(v)
            ax.plot(th.curve_pressure[k] / (study.E0 * th.slope_rms), th.curve_area[k], color=c,
                    ls=LINESTYLES[i], lw=1, label=f"q1 = {study.q1_label(q1)}" if i == 0 else None)
            p = select(study.points(), q1, v)
            draw_points(ax, abscissa(study, p, "slope"), p["area"], yerr=p["area_se"], color=c,
                        marker=("o", "s")[i % 2])
    from matplotlib.lines import Line2D
    handles = ax.get_legend_handles_labels()[0] + [
        Line2D([], [], color="0.3", ls=LINESTYLES[i], marker=("o", "s")[i % 2], mfc="none", label=f"v = {v:g} m/s")
        for i, v in enumerate(vs)]
    _area_axes(ax, r"$\sigma_0 / (E_0\, h'_{\rm rms})$", "Fig. 4: contact area (lines: theory, points: numerics)")
    ax.legend(handles=handles, fontsize=7)
    return save(fig, outdir, "fig4_area.png", seeds_note(study, study.points()))


def _area_axes(ax, xlabel, title):
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel("A/A$_0$")
    ax.set_ylim(1e-3, 1.05)
    ax.set_title(title, fontsize=10)


def master_figure(study, outdir):
    """Fig. 5: A/A0 against sigma0 / (E0 xi), every q1 and v; the theory's erf, the fitted numerical
    master curve and its small-load slope."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(5.5, 4.5))
    colors, marks = palette(study.velocities), markers(study.q1s)
    pts = study.points()
    for q1 in study.q1s:
        for v in study.velocities:
            p = select(pts, q1, v)
            draw_points(ax, abscissa(study, p, "xi"), p["area"], yerr=p["area_se"], color=colors[v],
                        marker=marks[q1], connect=False)
    x = np.geomspace(1e-3, 3.0, 300)
    ax.plot(x, erf(np.sqrt(2.0) * (1 - study.nu ** 2) * x), "k-", lw=1.2,
            label=r"theory: erf($\sqrt{2}(1-\nu^2)x$)")
    note = seeds_note(study, pts)
    xs = abscissa(study, pts, "xi")
    if enough_abscissas(xs):
        fit = fit_master_curve(xs, pts["area"])
        xf = np.geomspace(xs.min(), xs.max(), 200)
        ax.plot(xf, master_curve(fit, xf), color="tab:red", ls="--", lw=1, label="numerics: fitted master curve")
        kappa, kappa_se, _ = master_slope(study)
        scat = collapse(study)
        note += (f". Scatter of ln A/A0 around one fitted curve: {scat['xi'][0]:.3f} in this abscissa, "
                 f"{scat['slope'][0]:.3f} in Fig. 4's; small-load slope kappa = {kappa:.3f} ± {kappa_se:.2g} "
                 f"(theory {erf_small_load_slope(study.nu):.3f})")
    _area_axes(ax, r"$\sigma_0 / (E_0\, \xi(v))$", "Fig. 5: master curve")
    ax.legend(handles=ax.get_legend_handles_labels()[0] + velocity_handles(colors) + marker_handles(study, marks),
              fontsize=6.5)
    return save(fig, outdir, "fig5_master.png", note)

