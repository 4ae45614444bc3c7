"""``vecontact plot`` and ``vecontact report`` on a tiny study made here: every figure and table is
produced, from a complete and from a partial results file, and the numbers are those of the file."""
import json
import os
import re
import shutil
import subprocess
import sys

import h5py
import numpy as np
import pytest

from test_farm import vecontact, write_job
from vecontact.analysis.beyond import gamma_sensitivity
from vecontact.analysis.report import write_report
from vecontact.analysis.study import load_study
from vecontact.plot import MAPS_SKIPPED

PAPER_FIGURES = ["fig1_spectrum.png", "fig2_friction.png", "fig3_contact_maps.png", "fig4_area.png",
                 "fig5_master.png"]
BEYOND_FIGURES = ["theory_error.png", "morphology.png", "morphology_vs_v.png", "gamma_sensitivity.png"]
STUDY_COST = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "benchmarks", "study_cost.py")


def study_cost(path, *extra):
    """benchmarks/study_cost.py on ``path``: its last line's JSON (the run must succeed)."""
    p = subprocess.run([sys.executable, STUDY_COST, str(path), *extra], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    return json.loads(p.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def study_files(tmp_path_factory):
    """A 2-seed study at q1 = 8, 16 q0 (N = 64, 128), v = 0.01 and 1 m/s, 3 pressures, and a maps file
    with the contact field of one case per q1 at v = 10 m/s, A/A0 ~ 5 %."""
    d = tmp_path_factory.mktemp("study")
    job = write_job(d / "job.yaml", seeds=(1, 2))
    maps = write_job(d / "maps.yaml", output="maps.h5", velocity=(10.0,), fields=["contact"],
                     pressure={"area_min": 0.05, "area_max": 0.05, "num": 1})
    for j in (job, maps):
        p = vecontact(0, ["run", j, "--quiet"], cwd=d)
        assert p.returncode == 0, p.stdout + p.stderr
    return d


def _is_png(path):
    with open(path, "rb") as f:
        return f.read(8) == b"\x89PNG\r\n\x1a\n"


def _tables(text):
    """{anchor key: data rows of the table after it}."""
    out = {}
    for key, body in re.findall(r'<a id="(\w+)"></a>(.*?)(?=<a id=|\Z)', text, flags=re.S):
        rows = [line for line in body.splitlines() if line.startswith("| ") and not line.startswith("| --- |")]
        out[key] = [line.strip("| ").split(" | ") for line in rows[1:]]  # cells; header dropped
    return out


def test_plot_and_report_commands(study_files):
    d = study_files
    p = vecontact(0, ["plot", "out.h5", "--maps", "maps.h5", "-o", "figs"], cwd=d, timeout=300)
    assert p.returncode == 0, p.stderr
    assert MAPS_SKIPPED not in p.stdout
    for name in PAPER_FIGURES + BEYOND_FIGURES:
        assert os.path.join("figs", name) in p.stdout.split()
        assert (d / "figs" / name).stat().st_size > 10000 and _is_png(d / "figs" / name)
    p = vecontact(0, ["report", "out.h5", "--maps", "maps.h5", "-o", "numbers.md"], cwd=d)
    assert p.returncode == 0, p.stderr
    text = (d / "numbers.md").read_text()
    assert text.startswith("# Paper-reproduction numbers (generated: do not edit)")
    assert "`vecontact report out.h5 --maps maps.h5 -o numbers.md`" in text
    rows = _tables(text)
    q1v = 2 * 2                                                          # (q1, v) curves
    expect = {"convergence": 2, "seeds": 2, "hrms": 2, "peak": q1v, "high_load": q1v, "area_vs_v": 2 * 3,
              "collapse": 2 * (1 + 2), "kappa": 1 + 2, "maps": 2, "theory_error": q1v, "morphology": 2 * 3 * 2,
              "friction_estimates": q1v, "cost": 2}
    assert {k: len(rows[k]) for k in expect} == expect
    assert len(rows["gamma"]) >= q1v                                     # (q1, v, occupied A/A0 band)
    assert rows["convergence"][0][2:5] == ["12", "12", "0"]   # 2 seeds x 2 v x 3 p, all converged
    assert rows["seeds"][1][2:4] == ["1, 2", "1, 2"]
    assert {r[2] for r in rows["collapse"]} == {"2"}                      # q1 with results, per row
    assert "no common" not in text and "—" not in str(rows["area_vs_v"])
    # the cost table is sum(seconds x ranks) / 3600 of the file's rows
    with h5py.File(d / "out.h5", "r") as f:
        cases = f["cases"][()]
    for N, n, hours, *_ in rows["cost"]:
        mine = cases[cases["N"] == int(N)]
        assert int(n) == len(mine)
        assert float(hours) == pytest.approx(np.sum(mine["seconds"] * mine["ranks"]) / 3600, rel=5e-3)  # 3 digits


def test_gamma_recomputation_matches_the_file(study_files):
    rows, area_change, self_check = gamma_sensitivity(load_study(str(study_files / "out.h5")))
    assert len(rows) == 4
    assert area_change == 0.0          # gamma enters S(q) only: A/A0 = P(q1) is the same number
    assert self_check < 1e-12          # the same code and quadrature as the run: equal to rounding
    for r in rows:                     # S = gamma + (1 - gamma) P^2 grows with gamma, and so does mu
        assert np.all(r["mu"][0.45] < r["mu"][0.5]) and np.all(r["mu"][0.5] < r["mu"][5 / 9])


def test_partial_file(study_files, tmp_path):
    """A sweep still running: the second q1 has no rows and seed 2 is missing at the lowest pressures of
    the first. Figures (fig 3 skipped with a note: no --maps) and tables are all produced and say what is
    missing."""
    path = str(tmp_path / "partial.h5")
    shutil.copy(study_files / "out.h5", path)
    with h5py.File(path, "r+") as f:
        cases = f["cases"][()]
        first = cases["q1"] == cases["q1"].min()
        keep = cases[first & ((cases["seed"] == 1) | (cases["pressure"] > cases["pressure"][first].min()))]
        del f["cases"]
        f["cases"] = keep
        del f["diagnostics"]
    out = write_report(path, out=str(tmp_path / "n.md"))
    rows = _tables(open(out).read())
    assert rows["convergence"][1][2:6] == ["12", "0", "0", "12"]
    assert rows["seeds"][0][3] == "1, 2" and rows["seeds"][1][3] == "none"
    assert "q1 = 16 q0: no converged numerical cases in this file yet" in open(out).read()
    assert len(rows["peak"]) == 2 and len(rows["kappa"]) == 2
    assert {r[2] for r in rows["collapse"]} == {"1"}
    p = vecontact(0, ["plot", path, "-o", str(tmp_path / "figs")], cwd=tmp_path, timeout=300)
    assert p.returncode == 0, p.stderr
    assert p.stdout.splitlines()[-1] == f"vecontact: {MAPS_SKIPPED}"
    figs = p.stdout.splitlines()[:-1]
    assert [os.path.basename(f) for f in figs] == [f for f in PAPER_FIGURES + BEYOND_FIGURES if "fig3" not in f]
    assert sorted(os.listdir(tmp_path / "figs")) == sorted(os.path.basename(f) for f in figs)
    assert all(_is_png(f) for f in figs)


def test_collapse_rows_count_their_own_q1(study_files, tmp_path):
    """A velocity not yet solved at one q1: its collapse rows count the q1 that have it, not every q1."""
    path = str(tmp_path / "partial.h5")
    shutil.copy(study_files / "out.h5", path)
    with h5py.File(path, "r+") as f:
        cases = f["cases"][()]
        fast = (cases["q1"] == cases["q1"].max()) & (cases["velocity"] == cases["velocity"].max())
        del f["cases"]
        f["cases"] = cases[~fast]
        del f["diagnostics"]
    rows = _tables(open(write_report(path, out=str(tmp_path / "n.md"))).read())
    vmax = f"{float(cases['velocity'].max()):g} m/s"
    for r in rows["collapse"]:
        assert r[2] == ("1" if r[1] == vmax else "2"), r


def test_inset_window_is_around_a_large_patch():
    from vecontact.plot_maps import patch_window
    contact = np.zeros((256, 256), np.uint8)
    contact[100:110, 40:46] = 1                       # the largest patch: extent 10 -> window 40
    contact[200:203, 200:203] = 1
    assert patch_window(contact) == (85, 23, 40)      # centred on it: (100 + 110 - 40) // 2, (40 + 46 - 40) // 2
    contact[:] = 0
    contact[0:12, 0:12] = 1                           # touching the edge: its window does not fit
    contact[150:152, 150:152] = 1                     # so the next one's does (32 = the smallest window)
    assert patch_window(contact) == (135, 135, 32)
    contact[:] = 0
    for k in range(1, 11):                            # ten strips of 1 ... 10 points and one large
        contact[20 * k + 20, 100:100 + k] = 1         # patch: the 90th percentile skips the large one
    contact[0:40, 150:190] = 1
    assert patch_window(contact) == ((220 + 221 - 40) // 2, (100 + 110 - 40) // 2, 40)


def test_study_cost_benchmark(study_files, tmp_path):
    """benchmarks/study_cost.py: core-hours per N are the converged cases' seconds x ranks; a file
    against itself differs by nothing; the grid total is null until every planned case is in."""
    out = study_files / "out.h5"

    with h5py.File(out, "r") as f:
        cases = f["cases"][()]
    res = study_cost(out, "--reference", str(out), "--n", "64")
    for N in (64, 128):
        ok = (cases["N"] == N) & (cases["converged"] == 1)
        assert res["cases"][str(N)] == ok.sum() == res["planned"][str(N)] == 2 * 2 * 3
        want = (cases["seconds"][ok] * cases["ranks"][ok]).sum() / 3600
        assert abs(res["core_hours"][str(N)] - want) <= 1e-12 * want
    assert res["core_hours_n"] == res["core_hours"]["64"]
    assert res["compared"] == len(cases) and res["max_points"] == 0 and res["max_mu_rel"] == 0
    for N in ("64", "128"):
        assert abs(res["ratios"][N]["pairs"] - 1) <= 1e-12 and abs(res["ratios"][N]["core_hours"] - 1) <= 1e-12
        assert abs(res["ratios"][N]["machine"] - 1) <= 1e-12   # every case took the same path
    # a reference whose 64^2 cases took 4x the pairs and 2x the seconds, and whose 128^2 cases at
    # 1 m/s are missing: the ratios are over the cases in both only
    ref = tmp_path / "ref.h5"
    shutil.copy(out, ref)
    with h5py.File(ref, "r+") as f:
        c = f["cases"][()]
        c["fft_pairs"][c["N"] == 64] *= 4
        c["seconds"][c["N"] == 64] *= 2
        del f["cases"]
        f.create_dataset("cases", data=c[(c["N"] != 128) | (c["velocity"] != 1.0)])
    res = study_cost(out, "--reference", str(ref))
    assert res["compared"] == len(cases) - 2 * 3
    assert abs(res["ratios"]["64"]["pairs"] - 0.25) <= 1e-12 and abs(res["ratios"]["64"]["core_hours"] - 0.5) <= 1e-12
    assert abs(res["ratios"]["128"]["pairs"] - 1) <= 1e-12 and abs(res["ratios"]["128"]["core_hours"] - 1) <= 1e-12
    # 64^2: no case took the same path (4x the pairs), so no machine ratio; 128^2: all of them did
    assert res["ratios"]["64"]["machine"] is None and res["ratios"]["64"]["core_hours_same_machine"] is None
    assert abs(res["ratios"]["128"]["core_hours_same_machine"] - 1) <= 1e-12
    # --machine-commit: rows of other commits do not measure the machines
    from vecontact.io.results import read_strings
    from vecontact.status import read_status
    commit = str(read_status(str(out))["runs"][0].get("git_commit") or "?")
    res = study_cost(out, "--reference", str(ref), "--machine-commit", commit[:7])
    assert abs(res["ratios"]["128"]["machine"] - 1) <= 1e-12
    res = study_cost(out, "--reference", str(ref), "--machine-commit", "no-such-commit")
    assert res["ratios"]["128"]["machine"] is None and abs(res["ratios"]["128"]["core_hours"] - 1) <= 1e-12
    # a file resumed in two runs on machines of different speed: run 1 (every other 64^2 case) took twice
    # the time on the same path; each run is measured against its own same-path cases
    two = tmp_path / "two.h5"
    shutil.copy(out, two)
    with h5py.File(two, "r+") as f:
        c = f["cases"][()]
        later = np.flatnonzero(c["N"] == 64)[1::2]
        c["run"][later] = 1
        c["seconds"][later] *= 2
        del f["cases"]
        f.create_dataset("cases", data=c)
        runs = [json.loads(r) for r in read_strings(f, "runs")]
        runs.append(dict(runs[0], run=1, git_commit="f" * 40, started="later"))
        del f["runs"]
        f.create_dataset("runs", data=np.array([json.dumps(r) for r in runs], dtype=object),
                         dtype=h5py.string_dtype())
    res = study_cost(two, "--reference", str(out))
    r64 = res["ratios"]["64"]
    assert set(r64["runs"]) == {"0", "1"} and r64["runs"]["1"]["cases"] == later.size == r64["runs"]["1"]["same_path"]
    assert abs(r64["runs"]["0"]["machine"] - 1) <= 1e-12 and abs(r64["runs"]["1"]["machine"] - 2) <= 1e-12
    assert 1.1 < r64["machine"] < 1.9 and r64["core_hours"] > 1.1   # the two runs mixed
    assert abs(r64["core_hours_same_machine"] - 1) <= 1e-12         # each run at the reference's speed
    assert list(res["ratios"]["128"]["runs"]) == ["0"]
    # --machine-commit: the user names the rows that measure one machine for all runs
    r64 = study_cost(two, "--reference", str(out), "--machine-commit", commit[:7])["ratios"]["64"]
    assert r64["runs"]["1"]["machine"] is None and abs(r64["machine"] - 1) <= 1e-12
    assert abs(r64["core_hours_same_machine"] - r64["core_hours"]) <= 1e-12
    # a run none of whose cases took the reference's path: no speed for it, so no corrected total
    with h5py.File(two, "r+") as f:
        c = f["cases"][()]
        c["fft_pairs"][later] += 1
        del f["cases"]
        f.create_dataset("cases", data=c)
    r64 = study_cost(two, "--reference", str(out))["ratios"]["64"]
    assert r64["runs"]["1"]["machine"] is None and r64["runs"]["1"]["same_path"] == 0
    assert r64["core_hours_same_machine"] is None and abs(r64["machine"] - 1) <= 1e-12
    partial = tmp_path / "partial.h5"
    shutil.copy(out, partial)
    with h5py.File(partial, "r+") as f:
        keep = f["cases"][()][f["cases"]["N"] != 128]
        del f["cases"]
        f.create_dataset("cases", data=keep)
    res = study_cost(partial, "--n", "128")
    assert res["core_hours_n"] is None and "128" not in res["cases"]


def test_study_cost_pace_probe(study_files, tmp_path):
    """study_cost.py with the farm's pace probes: time per pair and core-seconds in raw pairs per N from
    the file's own probes; a reference solved the same way on a machine twice as slow (seconds and
    probes x2) costs twice the core-hours but the same paced cost; without every probe, no figure."""
    out = study_files / "out.h5"

    with h5py.File(out, "r") as f:
        cases = f["cases"][()]
        diag = [json.loads(d) for d in f["diagnostics"][()]]
    probe = np.array([d["raw_pair_seconds"] for d in diag])
    assert (probe > 0).all()
    res = study_cost(out)
    for N in (64, 128):
        ok = (cases["N"] == N) & (cases["converged"] == 1)
        got = res["paced"][str(N)]
        want = cases["seconds"][ok].sum() / (cases["fft_pairs"][ok] * probe[ok]).sum()
        assert abs(got["time_per_pair"] - want) <= 1e-12 * want
        want = (cases["seconds"][ok] * cases["ranks"][ok] / probe[ok]).sum()
        assert abs(got["raw_pair_units"] - want) <= 1e-12 * want
    slow = tmp_path / "slow.h5"
    shutil.copy(out, slow)
    with h5py.File(slow, "r+") as f:
        c = f["cases"][()]
        c["seconds"] *= 2
        del f["cases"]
        f.create_dataset("cases", data=c)
        text = [json.dumps(dict(d, raw_pair_seconds=2 * d["raw_pair_seconds"])) for d in diag]
        del f["diagnostics"]
        f.create_dataset("diagnostics", data=np.array(text, dtype=object), dtype=h5py.string_dtype())
    for N, r in study_cost(out, "--reference", str(slow))["ratios"].items():
        assert r["probed"] == r["cases"] and abs(r["core_hours"] - 0.5) <= 1e-12 and abs(r["paced"] - 1) <= 1e-12
    # one case without its probe: no paced figures for its N, and that case leaves the paced ratio
    with h5py.File(slow, "r+") as f:
        text = [json.loads(d) for d in f["diagnostics"][()]]
        first = int(np.flatnonzero(cases["N"] == 64)[0])
        text[first]["raw_pair_seconds"] = None
        del f["diagnostics"]
        f.create_dataset("diagnostics", data=np.array([json.dumps(d) for d in text], dtype=object),
                         dtype=h5py.string_dtype())
    res = study_cost(slow, "--reference", str(out))
    assert res["paced"]["64"] is None and res["paced"]["128"] is not None
    r64 = res["ratios"]["64"]
    assert r64["probed"] == r64["cases"] - 1 and abs(r64["paced"] - 1) <= 1e-12
