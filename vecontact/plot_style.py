"""Shared drawing conventions of the figures: colours per velocity, markers per q1, seed-averaged points
with error bars, the seeds note at the foot of each figure, saving.

Numerical points are seed means with the standard error over seeds as error bars; a point averaged
over one seed has no spread estimate and is drawn without a bar (the footnote says how many seeds
each q1 has).
"""
import os
import textwrap

import numpy as np

from vecontact.analysis.ensemble import seeds_summary, select

MARKERS = ("o", "s", "^", "D", "v", "P")
LINESTYLES = ("-", "--", "-.", ":")


def pyplot():
    """matplotlib.pyplot on the non-interactive Agg backend."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def palette(values, cmap="viridis"):
    """{value: colour} spread over the colour map (values in the given order)."""
    cm = pyplot().get_cmap(cmap)
    return {v: cm(x) for v, x in zip(values, np.linspace(0.0, 0.85, max(len(values), 1)))}


def markers(values):
    return {v: MARKERS[i % len(MARKERS)] for i, v in enumerate(values)}


def bar(se):
    """Error-bar half-lengths: the standard errors, 0 (no bar) where undefined (one seed)."""
    return np.nan_to_num(np.asarray(se, float), nan=0.0)


def draw_points(ax, x, y, yerr=None, xerr=None, color="k", marker="o", connect=True, label=None):
    """Seed-mean points with error bars (open markers), joined by a dotted line when ``connect``."""
    if len(x) == 0:
        return
    ax.errorbar(x, y, yerr=None if yerr is None else bar(yerr), xerr=None if xerr is None else bar(xerr),
                fmt=marker, color=color, mfc="none", ms=4, lw=0.8, capsize=1.5, ls=":" if connect else "none",
                label=label)


def friction_panel(ax, study, q1, colors, curves=None):
    """mu / <(grad h)^2> against A/A0 at one q1: theory lines and seed-mean points, per velocity.
    ``curves``: [(area, mu, line style)] with area, mu of shape (V, J); default the file's theory, solid."""
    th = study.theory(q1)
    s2 = th.slope_rms ** 2
    for area, mu, ls in curves or [(th.curve_area, th.curve_mu, "-")]:
        for k, v in enumerate(th.velocity):
            ax.plot(area[k], mu[k] / s2, color=colors[v], ls=ls, lw=1)
    for v in th.velocity:
        p = select(study.points(), q1, v)
        draw_points(ax, p["area"], p["mu"] / s2, yerr=p["mu_se"] / s2, xerr=p["area_se"], color=colors[v])
    ax.set_xscale("log")
    ax.set_xlabel("A/A$_0$")
    ax.set_ylabel(r"$\mu / \langle(\nabla h)^2\rangle$")


def seeds_note(study, points, q1s=None):
    """'numerics: mean ± s.e. over seeds; 32 q0: n = 4 of 4 seeds; 256 q0: no converged cases yet'."""
    parts = []
    for q1 in q1s or study.q1s:
        mine = points[points["q1"] == q1]
        want = len(study.seeds(q1))
        parts.append(f"{study.q1_label(q1)}: {seeds_summary(mine)} of {want} seed{'s' * (want > 1)}"
                     if len(mine) else f"{study.q1_label(q1)}: no converged cases yet")
    return ("numerics (points): mean ± standard error over seeds, n seeds per point (one seed: no bar); "
            + "; ".join(parts))


def velocity_handles(colors):
    from matplotlib.lines import Line2D
    return [Line2D([], [], color=c, label=f"v = {v:g} m/s") for v, c in colors.items()]


def marker_handles(study, marks):
    from matplotlib.lines import Line2D
    return [Line2D([], [], color="0.3", marker=m, mfc="none", ls="none", label=f"q1 = {study.q1_label(q)}")
            for q, m in marks.items()]


def save(fig, outdir, name, note=None, dpi=130, tight=True):
    """Write ``outdir/name`` with ``note`` (wrapped) at the foot of the figure; close it; return the path.
    ``tight``: fit the axes above the note with tight_layout (else the caller placed them)."""
    plt = pyplot()
    bottom = 0.0
    if note:
        width = int(fig.get_figwidth() * 16)
        text = "\n".join(textwrap.wrap(note, width))
        lines = text.count("\n") + 1
        bottom = min(0.4, (lines * 9.5 + 6) / (72.0 * fig.get_figheight()))
        fig.text(0.01, 0.01, text, fontsize=7, va="bottom", ha="left")
    if tight:
        fig.tight_layout(rect=(0, bottom, 1, 1))
    path = os.path.join(outdir, name)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path
