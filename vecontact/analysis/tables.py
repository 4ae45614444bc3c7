"""Tables of the report: a title, column names, rows of formatted cells, notes; written as markdown."""
import math
from dataclasses import dataclass, field

import numpy as np

#: A/A0 bands of the theory-error and gamma tables: [lo, hi) of the numerical A/A0.
AREA_BANDS = ((0.0, 0.02), (0.02, 0.08), (0.08, 0.3), (0.3, 1.0))


@dataclass
class Table:
    """``key``: short name (tests, anchors); ``rows``: lists of strings, one per column."""
    key: str
    title: str
    columns: list
    rows: list = field(default_factory=list)
    notes: list = field(default_factory=list)

    def markdown(self):
        lines = [f"### {self.title}", "", "| " + " | ".join(self.columns) + " |",
                 "|" + "|".join(" --- " for _ in self.columns) + "|"]
        lines += ["| " + " | ".join(row) + " |" for row in self.rows]
        if not self.rows:
            lines.append("| " + " | ".join(["(no data)"] + [""] * (len(self.columns) - 1)) + " |")
        lines += [""] + [f"- {n}" for n in self.notes]
        return "\n".join(lines).rstrip() + "\n"


def num(x, digits=3):
    """A number with ``digits`` significant digits (no exponent from 1e3 to 1e6: 3096 -> '3100');
    '—' for NaN or None."""
    if x is None or (isinstance(x, (float, np.floating)) and math.isnan(x)):
        return "—"
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    rounded = float(f"{x:.{digits}g}")
    return f"{rounded:.0f}" if 1e3 <= abs(rounded) < 1e6 else f"{x:.{digits}g}"


def pm(x, se, digits=3):
    """'x ± se' (se with 2 significant digits), or 'x' when se is NaN (a single seed)."""
    if se is None or math.isnan(se):
        return num(x, digits)
    return f"{num(x, digits)} ± {se:.2g}"


def percent(x, se=None):
    """A relative quantity as a signed percentage, '+12.3 %' (± s.e. when given and finite)."""
    if x is None or math.isnan(x):
        return "—"
    if se is None or math.isnan(se):
        return f"{100 * x:+.1f} %"
    return f"{100 * x:+.1f} ± {100 * se:.1f} %"


def band_label(band):
    lo, hi = band
    if lo == 0:
        return f"< {100 * hi:g} %"
    if hi >= 1:
        return f"≥ {100 * lo:g} %"
    return f"{100 * lo:g}–{100 * hi:g} %"


def in_band(area, band):
    """Mask of the A/A0 values in [lo, hi) (hi = 1 included)."""
    lo, hi = band
    return (area >= lo) & ((area < hi) | (hi >= 1))
