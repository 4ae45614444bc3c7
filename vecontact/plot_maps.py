"""Fig. 3: contact maps (black = contact) from a maps results file (e.g. jobs/paper-maps.yaml), one panel
per q1, the large system first, each with an enlarged inset of a contact patch.

The maps file stores ``/fields/<case>/contact`` (uint8, axis 0 = x = the sliding direction, attrs N, L
in m, spacing in m, area, velocity in m/s). The map is drawn with x horizontal, so the rubber slides to
the right (arrow "v"). Only converged cases (status 1 in the maps file's /cases) are drawn; a q1 without
a converged map gets a panel that says so.
"""
import h5py
import numpy as np
from scipy import ndimage

from vecontact.io.results import case_key
from vecontact.plot_style import pyplot, save

#: Inset window: 4 x the patch's extent, at least this many grid points, at most N / 4.
INSET_MIN_SIDE = 32
INSET_PATCH_FACTOR = 4
#: The inset's patch: the largest after skipping this fraction of the patches (the 90th percentile).
INSET_PERCENTILE_SKIP = 0.1


def read_maps(maps):
    """{q1: (attrs, contact)} for the converged cases of the maps Study that have a contact field
    (the fastest velocity when a q1 has several)."""
    converged = {case_key(r) for r in maps.converged()}
    found = {}
    with h5py.File(maps.path, "r") as f:
        for name in f.get("fields", {}):
            g = f["fields"][name]
            a = dict(g.attrs)
            key = (float(a["q1"]), int(a["seed"]), float(a["velocity"]), float(a["pressure"]))
            if "contact" not in g or key not in converged:
                continue
            if key[0] not in found or key[2] > found[key[0]][0]["velocity"]:
                found[key[0]] = (a, g["contact"][()])
    return found


def patch_window(contact):
    """(i0, j0, side): a square window (grid indices along x, y) around a large 4-connected patch,
    ``INSET_PATCH_FACTOR`` times its extent (between INSET_MIN_SIDE and N / 4 points): the patch at the
    90th percentile of sizes (the largest ones of a large system are extended clusters that a window
    cannot enlarge), or the next one down, then up, whose window fits inside the map; the centre of the
    map when none fits."""
    N = contact.shape[0]
    labels, n = ndimage.label(contact)
    if n:
        sizes = ndimage.sum_labels(contact, labels, np.arange(1, n + 1))
        boxes = ndimage.find_objects(labels)
        by_size = np.argsort(sizes)[::-1]
        start = int(INSET_PERCENTILE_SKIP * n)
        for k in np.concatenate([by_size[start:], by_size[:start][::-1]]):
            sx, sy = boxes[k]
            extent = max(sx.stop - sx.start, sy.stop - sy.start)
            side = int(min(max(INSET_PATCH_FACTOR * extent, INSET_MIN_SIDE), N // 4))
            i0, j0 = (sx.start + sx.stop - side) // 2, (sy.start + sy.stop - side) // 2
            if 0 <= i0 and i0 + side <= N and 0 <= j0 and j0 + side <= contact.shape[1]:
                return i0, j0, side
    side = max(N // 8, 1)
    return (N - side) // 2, (contact.shape[1] - side) // 2, side


def map_panel(ax, attrs, contact, title):
    """One map (x horizontal, in um), its inset and the sliding arrow."""
    L = float(attrs["L"]) * 1e6
    N = contact.shape[0]
    dx = L / N
    show = dict(cmap="gray_r", vmin=0, vmax=1, origin="lower", interpolation="antialiased")
    ax.imshow(contact.T, extent=(0, L, 0, L), **show)
    ax.set_xlabel("x (µm), sliding direction")
    ax.set_ylabel("y (µm)")
    i0, j0, side = patch_window(contact)
    right, top = (i0 + side / 2) > N / 2, (j0 + side / 2) > N / 2
    inset = ax.inset_axes([0.02 if right else 0.56, 0.02 if top else 0.56, 0.42, 0.42])
    inset.imshow(contact[i0:i0 + side, j0:j0 + side].T,
                 extent=(i0 * dx, (i0 + side) * dx, j0 * dx, (j0 + side) * dx), **show)
    inset.set_xticks([])
    inset.set_yticks([])
    for s in inset.spines.values():
        s.set_edgecolor("tab:red")
        s.set_linewidth(1.2)
    inset.text(0.03, 0.03, f"×{N / side:.0f}", transform=inset.transAxes, fontsize=7, color="tab:red",
               bbox=dict(fc="white", ec="none", pad=1))
    ax.indicate_inset_zoom(inset, edgecolor="tab:red")
    ax.annotate("", xy=(0.34, 1.03), xytext=(0.02, 1.03), xycoords="axes fraction",
                arrowprops=dict(arrowstyle="-|>", color="tab:blue", lw=1.6))
    ax.text(0.37, 1.03, f"v = {float(attrs['velocity']):g} m/s", transform=ax.transAxes, va="center",
            fontsize=8, color="tab:blue")
    ax.set_title(title, fontsize=9, pad=16)


def maps_figure(maps, outdir):
    """fig3_contact_maps.png from the maps Study (large q1 first)."""
    plt = pyplot()
    found = read_maps(maps)
    q1s = sorted(maps.q1s, reverse=True)
    fig, axes = plt.subplots(1, len(q1s), figsize=(5.2 * len(q1s), 6.0), squeeze=False)
    for k, (ax, q1) in enumerate(zip(axes[0], q1s)):
        name = "large" if k == 0 and len(q1s) > 1 else "small" if k == len(q1s) - 1 and len(q1s) > 1 else ""
        head = f"({chr(97 + k)}) {name} system: q1 = {maps.q1_label(q1)}".replace(")  ", ") ")
        if q1 not in found:
            ax.text(0.5, 0.5, "no converged contact map in\n" + maps.path, ha="center", va="center",
                    transform=ax.transAxes, fontsize=8)
            ax.set_axis_off()
            ax.set_title(head, fontsize=9)
            continue
        a, contact = found[q1]
        map_panel(ax, a, contact, f"{head}, N = {int(a['N'])}\nA/A0 = {float(a['area']):.3f}, "
                                  f"σ0 = {float(a['pressure']):.3g} Pa, seed {int(a['seed'])}")
    fig.subplots_adjust(left=0.07, right=0.98, top=0.84, bottom=0.14, wspace=0.25)
    note = (f"Fig. 3: contact morphology (black: contact), from {maps.path}: one surface realisation per map "
            f"(no seed average). Inset: a window around a large patch (90th percentile of sizes), enlarged; "
            f"the red box marks it on the map.")
    return save(fig, outdir, "fig3_contact_maps.png", note, dpi=200, tight=False)
