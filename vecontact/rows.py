"""One row of ``/cases`` per case: the columns, the theory row, the solved row and the diagnostics.

Every column of the results table is named here once (name, dtype, unit, description).  The sweep
(:mod:`vecontact.cases`) builds the theory row, the task farm (:mod:`vecontact.farm`) the solved
row, the results file (:mod:`vecontact.io.results`) writes them and ``vecontact status`` reads them.

Filled by name: the numerical columns carry the names of the solver's
:class:`~vecontact.solver.ContactResult` attributes (``SOLVER_COLUMNS``), the morphology columns
those of :class:`~vecontact.analysis.morphology.Morphology` (``MORPHOLOGY_COLUMNS``).

Diagnostics are what a row does not hold about a solve: one JSON object per row in
``/diagnostics``, under the names the solver uses (``DIAGNOSTICS``): the ``ContactResult``
attributes ``reason``, ``method``, ``measures``, ``fft_pairs_by_level`` and the keys of its own
``diagnostics`` dict.  ``REASON`` is the key ``vecontact status`` and the progress line read.
"""
import numpy as np

# (name, dtype, unit, description)
COLUMNS = [
    ("q1", "f8", "1/m", "large-wavevector roughness cut-off"),
    ("seed", "i8", "", "surface realisation"),
    ("velocity", "f8", "m/s", "sliding speed"),
    ("pressure", "f8", "Pa", "nominal pressure sigma0"),
    ("theory_area", "f8", "", "Persson A/A0 = P(q1)"),
    ("theory_mu", "f8", "", "Persson viscoelastic friction coefficient"),
    ("xi", "f8", "", "effective rms slope xi(v)"),
    ("slope_rms", "f8", "", "rms slope <|grad h|^2>^1/2 of the spectrum"),
    ("status", "i1", "", "1 converged, -1 not converged, 0 theory only"),
    ("area", "f8", "", "numerical A/A0"),
    ("mu", "f8", "", "numerical friction, dissipation estimate"),
    ("mu_geometric", "f8", "", "numerical friction, <p dh/dx>/sigma0"),
    ("mean_gap", "f8", "m", "mean interfacial gap"),
    ("rigid_position", "f8", "m", "rigid-body position of the rubber"),
    ("converged", "?", "", "numerical solve converged"),
    ("iterations", "i8", "", "nonlinear iterations"),
    ("linear_iterations", "i8", "", "Krylov iterations"),
    ("fft_pairs", "f8", "", "FFT pairs, fine-grid equivalent"),
    ("residual", "f8", "", "final scale-free residual"),
    ("seconds", "f8", "s", "wall time of the solve"),
    ("N", "i8", "", "grid points per side"),
    ("ranks", "i8", "", "ranks that solved the case"),
    ("run", "i8", "", "index into /runs of the run that wrote the row (-1: written before /runs existed)"),
    # contact morphology of the solution (vecontact.analysis.morphology; 4-connected, periodic)
    ("patches", "i8", "", "contact patches, joined across the periodic boundaries"),
    ("percolating", "i8", "", "patches that wrap around the period (left out of the anisotropy)"),
    ("mean_patch_area", "f8", "m^2", "contact area / patches"),
    ("perimeter", "f8", "m", "total length of the contact boundary in the L x L cell"),
    ("anisotropy_extent", "f8", "", "mean patch extent along x (sliding) / mean extent along y"),
    ("anisotropy_moments", "f8", "", "sqrt(sum of patch second moments along x / along y)"),
]
CASE_DTYPE = np.dtype([(n, t) for n, t, _, _ in COLUMNS])
KEY = ("q1", "seed", "velocity", "pressure")
THEORY_COLUMNS = ("theory_area", "theory_mu", "xi", "slope_rms")
#: columns copied from the ContactResult attribute of the same name
SOLVER_COLUMNS = ("area", "mu", "mu_geometric", "mean_gap", "rigid_position", "converged", "iterations",
                  "linear_iterations", "fft_pairs", "residual", "seconds")
#: columns copied from the Morphology attribute of the same name
MORPHOLOGY_COLUMNS = ("patches", "percolating", "mean_patch_area", "perimeter", "anisotropy_extent",
                      "anisotropy_moments")
CONVERGED, NOT_CONVERGED, THEORY_ONLY = 1, -1, 0
STATUS_CODES = "1: converged; -1: not converged (numerical columns are NOT results); 0: theory only"

REASON = "reason"
#: diagnostics taken from the ContactResult attribute of the same name
RESULT_DIAGNOSTICS = (REASON, "method", "measures", "fft_pairs_by_level")
#: diagnostics taken from the ContactResult's own ``diagnostics`` dict: (key, value when absent)
SOLVER_DIAGNOSTICS = (("levels", ()), ("history", ()), ("active_set_changes", ()), ("linear_history", ()),
                      ("step_modes", ()), ("measure_checks", ()), ("single_iterations", None),
                      ("float32_pairs", None), ("mixed_pairs", None), ("carried_directions", None), ("stalls", None),
                      ("smoothed_steps", None), ("kappa", None), ("ell", None))
#: diagnostics the farm measures around the solve
FARM_DIAGNOSTICS = ("raw_pair_seconds",)
DIAGNOSTICS = RESULT_DIAGNOSTICS + tuple(k for k, _ in SOLVER_DIAGNOSTICS) + FARM_DIAGNOSTICS


def empty_row():
    """A row with numerical columns set to 'absent' (NaN / -1 / False), status 0 (theory only)."""
    row = np.zeros((), dtype=CASE_DTYPE)
    for name, t, _, _ in COLUMNS:
        if t == "f8":
            row[name] = np.nan
        elif t == "i8":
            row[name] = -1
    row["status"] = THEORY_ONLY
    row["converged"] = False
    return row


def case_key(row):
    """(q1 in 1/m, seed, velocity in m/s, pressure in Pa) of a row: the case it belongs to."""
    return (float(row["q1"]), int(row["seed"]), float(row["velocity"]), float(row["pressure"]))


def theory_row(key, area, mu, xi, slope_rms):
    """The row of case ``key`` (q1 1/m, seed, velocity m/s, pressure Pa) with Persson's A/A0 and
    friction coefficient, the effective rms slope xi(v) and the spectrum's rms slope (all
    dimensionless); the numerical columns absent."""
    row = empty_row()
    for name, value in zip(KEY, key):
        row[name] = value
    for name, value in zip(THEORY_COLUMNS, (area, mu, xi, slope_rms)):
        row[name] = value
    return row


def solved_row(theory, result, N, ranks, morphology=None):
    """A copy of the ``theory`` row with the solve's columns: ``result`` (a ContactResult, or anything
    with its SOLVER_COLUMNS attributes), the grid ``N`` (points per side), the ``ranks`` that solved
    it and, when given, the ``morphology`` of its contact set (a Morphology)."""
    row = theory.copy()
    for name in SOLVER_COLUMNS:
        row[name] = getattr(result, name)
    row["N"], row["ranks"] = N, ranks
    row["status"] = CONVERGED if result.converged else NOT_CONVERGED
    if morphology is not None:
        for name in MORPHOLOGY_COLUMNS:
            row[name] = getattr(morphology, name)
    return row


def diagnostics(result, raw_pair_seconds=None):
    """The ``/diagnostics`` object of a solve (JSON-serialisable dict, keys DIAGNOSTICS in order):
    the reason, the method, the final measures, FFT pairs per grid size (raw, unweighted), the
    per-level Newton counts, the fine grid's residual history and active-set changes, ..., and the
    farm's ``raw_pair_seconds`` (s: one float64 FFT pair timed on the case's grid and ranks after the
    solve, farm/case.py; None when not measured)."""
    out = {name: getattr(result, name) for name in RESULT_DIAGNOSTICS}
    out["fft_pairs_by_level"] = {str(n): v for n, v in result.fft_pairs_by_level.items()}  # JSON keys: str
    own = result.diagnostics
    out.update((name, own.get(name, absent)) for name, absent in SOLVER_DIAGNOSTICS)
    out["raw_pair_seconds"] = None if raw_pair_seconds is None else float(raw_pair_seconds)
    return out
