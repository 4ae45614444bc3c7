"""The /cases row schema (vecontact.rows): the theory row, the solved row and the diagnostics."""
import json

import h5py
import numpy as np

from vecontact.analysis.morphology import Morphology
from vecontact.io.results import ResultsFile
from vecontact.rows import (CASE_DTYPE, COLUMNS, DIAGNOSTICS, KEY, MORPHOLOGY_COLUMNS, SOLVER_COLUMNS,
                            THEORY_COLUMNS, diagnostics, empty_row, solved_row, theory_row)
from vecontact.solver import ContactResult

# the columns as written by 356cf30 (before the schema moved here): name -> (dtype, unit)
SCHEMA_356CF30 = {
    "q1": ("f8", "1/m"), "seed": ("i8", ""), "velocity": ("f8", "m/s"), "pressure": ("f8", "Pa"),
    "theory_area": ("f8", ""), "theory_mu": ("f8", ""), "xi": ("f8", ""), "slope_rms": ("f8", ""),
    "status": ("i1", ""), "area": ("f8", ""), "mu": ("f8", ""), "mu_geometric": ("f8", ""),
    "mean_gap": ("f8", "m"), "rigid_position": ("f8", "m"), "converged": ("?", ""), "iterations": ("i8", ""),
    "linear_iterations": ("i8", ""), "fft_pairs": ("f8", ""), "residual": ("f8", ""), "seconds": ("f8", "s"),
    "N": ("i8", ""), "ranks": ("i8", ""), "run": ("i8", ""), "patches": ("i8", ""), "percolating": ("i8", ""),
    "mean_patch_area": ("f8", "m^2"), "perimeter": ("f8", "m"), "anisotropy_extent": ("f8", ""),
    "anisotropy_moments": ("f8", ""),
}
KEY_8E6 = (8.0e6, 3, 0.01, 2.5e4)        # q1 (1/m), seed, velocity (m/s), pressure (Pa)


def _result(converged=True):
    """A ContactResult with a distinct value in every field a row or the diagnostics take."""
    return ContactResult(
        area=0.125, mu=0.0375, mu_geometric=0.0371, mean_gap=2.5e-7, rigid_position=3.25e-7,
        converged=converged, iterations=11, linear_iterations=97, fft_pairs=123.5, residual=4.0e-9,
        seconds=1.75, reason="converged" if converged else "diverged_max_it", method="snes",
        fft_pairs_by_level={32: 40.0, 64: 100.0},
        measures={"complementarity": 1e-9, "penetration": 2e-9, "force": 4e-9},
        diagnostics={"levels": [{"N": 64, "iterations": 11}], "history": [(0, 1.0), (11, 4e-9)],
                     "active_set_changes": [5, 0], "linear_history": [9, 8], "step_modes": ["newton"],
                     "kappa": 0.5, "ell": 1e-6, "hrms": 2e-6, "k": 3})


def _morphology():
    return Morphology(patches=17, percolating=1, area_fraction=0.125, mean_patch_area=2.0e-12,
                      perimeter=3.5e-4, anisotropy_extent=1.25, anisotropy_moments=1.125)


def test_schema_and_units_unchanged():
    assert {n: (t, u) for n, t, u, _ in COLUMNS} == SCHEMA_356CF30
    assert list(CASE_DTYPE.names) == list(SCHEMA_356CF30)       # column order, too
    # every column is filled by exactly one of: key, theory, solver, morphology, N/ranks/status, run
    filled = KEY + THEORY_COLUMNS + SOLVER_COLUMNS + MORPHOLOGY_COLUMNS + ("N", "ranks", "status", "run")
    assert sorted(filled) == sorted(CASE_DTYPE.names)


def test_theory_row():
    row = theory_row(KEY_8E6, 0.0625, 0.021, 0.35, 0.42)
    assert tuple(row[k].item() for k in KEY) == KEY_8E6
    assert [row[k].item() for k in THEORY_COLUMNS] == [0.0625, 0.021, 0.35, 0.42]
    assert row["status"] == 0 and not row["converged"]
    # everything else is absent (NaN / -1), as in an empty row
    for name in set(CASE_DTYPE.names) - set(KEY) - set(THEORY_COLUMNS) - {"status", "converged"}:
        np.testing.assert_array_equal(row[name], empty_row()[name], err_msg=name)


def test_solved_row_sets_every_column():
    theory = theory_row(KEY_8E6, 0.0625, 0.021, 0.35, 0.42)
    res, m = _result(), _morphology()
    row = solved_row(theory, res, 64, 2, m)
    expected = dict(zip(KEY, KEY_8E6), theory_area=0.0625, theory_mu=0.021, xi=0.35, slope_rms=0.42,
                    status=1, area=0.125, mu=0.0375, mu_geometric=0.0371, mean_gap=2.5e-7, rigid_position=3.25e-7,
                    converged=True, iterations=11, linear_iterations=97, fft_pairs=123.5, residual=4.0e-9,
                    seconds=1.75, N=64, ranks=2, run=-1, patches=17, percolating=1, mean_patch_area=2.0e-12,
                    perimeter=3.5e-4, anisotropy_extent=1.25, anisotropy_moments=1.125)
    assert set(expected) == set(CASE_DTYPE.names)
    for name, value in expected.items():
        assert row[name].item() == value, name          # copies: exact
    assert theory["status"] == 0 and np.isnan(theory["area"])  # the theory row is left alone
    # not converged: status -1; without a morphology (off the group's leader) those columns stay absent
    bad = solved_row(theory, _result(converged=False), 64, 2)
    assert bad["status"] == -1 and not bad["converged"] and bad["area"] == 0.125
    assert bad["patches"] == -1 and np.isnan(bad["perimeter"])


def test_diagnostics_names_and_file(tmp_path):
    """The diagnostics object has the solver's names (DIAGNOSTICS, in order) and reaches /diagnostics
    next to its row; status's key is among them."""
    res = _result(converged=False)
    d = diagnostics(res)
    assert list(d) == list(DIAGNOSTICS) and "reason" in DIAGNOSTICS
    assert d["reason"] == "diverged_max_it" and d["fft_pairs_by_level"] == {"32": 40.0, "64": 100.0}
    assert d["levels"] == res.diagnostics["levels"] and d["kappa"] == 0.5 and d["ell"] == 1e-6
    assert "hrms" not in d                              # only the named keys
    assert d["raw_pair_seconds"] is None and diagnostics(res, raw_pair_seconds=0.25)["raw_pair_seconds"] == 0.25
    # keys the solver did not fill: empty lists / None
    res.diagnostics = {}
    empty = diagnostics(res)
    assert json.loads(json.dumps(empty))["history"] == [] and empty["kappa"] is None
    # through the results file
    path = str(tmp_path / "r.h5")
    w = ResultsFile.open(path, "", "h", 1)
    w.add_row(solved_row(theory_row(KEY_8E6, 0.0625, 0.021, 0.35, 0.42), _result(False), 64, 1, _morphology()),
              diagnostics=d)
    w.commit()
    with h5py.File(path, "r") as f:
        stored = json.loads(f["diagnostics"][0])
        units = json.loads(f["cases"].attrs["units"])
        assert f["cases"][0]["status"] == -1 and f["cases"][0]["run"] == 0
    assert stored["reason"] == "diverged_max_it" and stored["history"] == [[0, 1.0], [11, 4e-9]]
    assert units == {n: u for n, (_, u) in SCHEMA_356CF30.items()}


def test_columns_filled_by_name_exist_in_their_source():
    """The columns copied by name from the solver's result and the morphology are fields of those
    classes (a renamed field would otherwise fail only in the first solve of a job)."""
    assert set(SOLVER_COLUMNS) <= set(ContactResult.__dataclass_fields__)
    assert set(MORPHOLOGY_COLUMNS) <= set(Morphology.__dataclass_fields__)
