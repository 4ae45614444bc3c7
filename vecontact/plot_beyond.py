"""Figures past the paper (numbers: vecontact.analysis.beyond):

- theory_error.png: theory / numerics - 1 for mu and A/A0 against the numerical A/A0, one line per
  (q1, v): where the mean-field theory breaks;
- morphology.png: patches, mean patch area, perimeter and the two anisotropies against A/A0 per v;
- morphology_vs_v.png: the same at fixed A/A0 (1 %, 5 %, 20 %) against v;
- gamma_sensitivity.png: the theory's mu / <(grad h)^2> for gamma = 0.45, 0.5, 5/9 next to the numerics.
"""
import numpy as np

from vecontact.analysis.beyond import (GAMMAS, MORPHOLOGY, MORPHOLOGY_AREAS, gamma_curves,
                                       morphology_at_areas, theory_error)
from vecontact.analysis.ensemble import select
from vecontact.plot_style import (LINESTYLES, draw_points, friction_panel, marker_handles, markers, palette,
                                  pyplot, save, seeds_note, velocity_handles)


def figures(study, outdir):
    return [theory_error_figure(study, outdir), morphology_figure(study, outdir),
            morphology_velocity_figure(study, outdir), gamma_figure(study, outdir)]


def _no_results(ax, study):
    if not study.q1_with_results():
        ax.text(0.5, 0.5, f"no converged numerical cases in\n{study.path}", ha="center", va="center",
                transform=ax.transAxes, fontsize=8)


def theory_error_figure(study, outdir):
    plt = pyplot()
    colors, marks = palette(study.velocities), markers(study.q1s)
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2))
    for ax, (quantity, label) in zip(axes, (("mu", r"$\mu$"), ("area", "A/A$_0$"))):
        for q1 in study.q1_with_results():
            for v in study.velocities:
                p = select(study.points(), q1, v)
                err, se = theory_error(p, quantity)
                draw_points(ax, p["area"], 100 * err, yerr=100 * se, xerr=p["area_se"], color=colors[v],
                            marker=marks[q1])
        ax.axhline(0.0, color="k", lw=0.8)
        ax.set_xscale("log")
        ax.set_xlabel("A/A$_0$ (numerics)")
        ax.set_ylabel(f"theory / numerics - 1 in {label} (%)")
        _no_results(ax, study)
    axes[0].legend(handles=velocity_handles(colors) + marker_handles(study, marks), fontsize=7)
    fig.suptitle("Where the mean-field theory errs (theory at the same σ0)", fontsize=10)
    return save(fig, outdir, "theory_error.png", seeds_note(study, study.points()))


def _morphology_axes(fig):
    axes = fig.subplots(2, 3).ravel()
    axes[-1].set_axis_off()
    for ax, (_, label, _, log) in zip(axes, MORPHOLOGY):
        ax.set_ylabel(label)
        if log:
            ax.set_yscale("log")
    return axes


def morphology_figure(study, outdir):
    plt = pyplot()
    colors, marks = palette(study.velocities), markers(study.q1s)
    fig = plt.figure(figsize=(11, 6.5))
    axes = _morphology_axes(fig)
    for ax, (col, _, factor, _) in zip(axes, MORPHOLOGY):
        for q1 in study.q1_with_results():
            for v in study.velocities:
                p = select(study.points(), q1, v)
                draw_points(ax, p["area"], factor * p[col], yerr=factor * p[f"{col}_se"], xerr=p["area_se"],
                            color=colors[v], marker=marks[q1])
        ax.set_xscale("log")
        ax.set_xlabel("A/A$_0$")
        _no_results(ax, study)
    axes[-1].legend(handles=velocity_handles(colors) + marker_handles(study, marks), fontsize=8, loc="center")
    fig.suptitle("Contact morphology against A/A0 per sliding speed (x = sliding direction)", fontsize=10)
    return save(fig, outdir, "morphology.png", seeds_note(study, study.points()))


def morphology_velocity_figure(study, outdir):
    plt = pyplot()
    acol, marks = palette(MORPHOLOGY_AREAS, "plasma"), markers(study.q1s)
    fig = plt.figure(figsize=(11, 6.5))
    axes = _morphology_axes(fig)
    vs = np.array(study.velocities)
    for q1 in study.q1_with_results():
        curves = [morphology_at_areas(select(study.points(), q1, v)) for v in vs]
        for i, a in enumerate(MORPHOLOGY_AREAS):
            for ax, (col, _, factor, _) in zip(axes, MORPHOLOGY):
                y = np.array([c[col][0][i] for c in curves]) * factor
                se = np.array([c[col][1][i] for c in curves]) * factor
                draw_points(ax, vs, y, yerr=se, color=acol[a], marker=marks[q1])
    for ax in axes[:len(MORPHOLOGY)]:
        ax.set_xscale("log")
        ax.set_xlabel("v (m/s)")
        _no_results(ax, study)
    from matplotlib.lines import Line2D
    handles = [Line2D([], [], color=c, label=f"A/A0 = {a:g}") for a, c in acol.items()]
    axes[-1].legend(handles=handles + marker_handles(study, marks), fontsize=8, loc="center")
    fig.suptitle("Contact morphology against v at fixed A/A0 (seed means interpolated in ln A/A0)", fontsize=10)
    return save(fig, outdir, "morphology_vs_v.png", seeds_note(study, study.points()))


def gamma_figure(study, outdir):
    """mu / <(grad h)^2> against A/A0, one panel per q1 with results (every q1 when there are none)."""
    plt = pyplot()
    colors = palette(study.velocities)
    q1s = study.q1_with_results() or study.q1s
    fig, axes = plt.subplots(1, len(q1s) + 1, figsize=(4.6 * len(q1s) + 2, 4.2),
                             gridspec_kw={"width_ratios": [1] * len(q1s) + [0.45]})
    for ax, q1 in zip(axes, q1s):
        curves = [gamma_curves(study, q1, g) + (ls,) for g, ls in zip(GAMMAS, LINESTYLES)]
        friction_panel(ax, study, q1, colors, curves)
        ax.set_title(f"q1 = {study.q1_label(q1)}", fontsize=9)
        _no_results(ax, study)
    from matplotlib.lines import Line2D
    handles = [Line2D([], [], color="0.3", ls=ls, label=f"theory, γ = {g:.3g}") for g, ls in zip(GAMMAS, LINESTYLES)]
    axes[-1].set_axis_off()
    axes[-1].legend(handles=handles + velocity_handles(colors), fontsize=7, loc="center")
    fig.suptitle("Sensitivity of the theory to γ in S(q) = γ + (1-γ)P²\n(lines: theory; points: numerics; "
                 "A/A0 does not depend on γ)", fontsize=9)
    return save(fig, outdir, "gamma_sensitivity.png", seeds_note(study, study.points(), q1s))
