"""Job validation: every bad job gives one line naming the key, exit 2, no traceback, no file."""
import copy
import os
import re
import subprocess
import sys

import numpy as np
import pytest
import yaml

from vecontact import job as jobs
from vecontact.errors import InputError

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

GOOD = {
    "output": "out.h5",
    "surface": {"spectrum": "self-affine", "q0": 2.5e5, "qr": 1.0e6, "q1": [2.0e6, 4.0e6],
                "hurst": 0.8, "C0": 1.0616e-28, "null_band": 4, "seeds": [1, 2]},
    "material": {"model": "havriliak-negami", "E0": 3.0e6, "Einf": 3.0e9, "alpha": 0.5,
                 "beta": 0.5, "tau": 1.0e-10, "nu": 0.5},
    "sweep": {"velocity": [0.01, 1.0], "pressure": {"min": 1.0e4, "max": 1.0e6, "num": 3}},
    "theory": {"gamma": 0.5},
    "numerics": {"enabled": False},
}


def _bad(path, value):
    """GOOD with the dotted key set to value (or removed when value is ...)."""
    job = copy.deepcopy(GOOD)
    keys = path.split(".")
    d = job
    for k in keys[:-1]:
        d = d[k]
    if value is ...:
        del d[keys[-1]]
    else:
        d[keys[-1]] = value
    return job


def _refused(tmp_path, job, *args, timeout=120):
    """Run ``job`` (with its output in tmp_path) through the CLI, which must refuse it: exit status 2,
    one line on stderr, no traceback, nothing written but the job file.  Returns that line."""
    job["output"] = str(tmp_path / "out.h5")
    path = tmp_path / "job.yaml"
    path.write_text(yaml.safe_dump(job))
    proc = subprocess.run([sys.executable, "-m", "vecontact", "run", str(path)] + list(args), capture_output=True,
                          text=True, cwd=tmp_path, timeout=timeout)
    assert proc.returncode == 2, proc.stdout + proc.stderr[-2000:]
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in proc.stderr + proc.stdout, proc.stderr
    assert sorted(os.listdir(tmp_path)) == ["job.yaml"]
    return lines[0]


# (change, key the message must name)
BAD = [
    (("surface.q1", [5.0e5]), "surface.q1"),                     # q1 <= qr
    (("surface.qr", 1.0e5), "surface.qr"),                       # qr < q0
    (("surface.hurst", 1.0), "surface.hurst"),                   # H must be < 1
    (("surface.hurst", 0.0), "surface.hurst"),                   # H must be > 0
    (("surface.C0", -1.0), "surface.C0"),
    (("surface.q1", [2.0e6, 2.1e6]), "surface.q1"),              # non-integer grid size
    (("surface.colour", "red"), "surface.colour"),               # unknown key
    (("surface.seeds", [1.5]), "surface.seeds"),                 # not an integer
    (("surface.spectrum", "fractal"), "surface.spectrum"),
    (("material.model", "maxwell"), "material.model"),
    (("material.Einf", 1.0e6), "material.Einf"),                 # Einf < E0
    (("material.nu", 0.7), "material.nu"),
    (("material.alpha", 1.5), "material.alpha"),
    (("material.tau", ...), "material.tau"),                     # missing
    (("sweep.pressure", [1.0e4, -5.0]), "sweep.pressure"),       # pressure <= 0
    (("sweep.pressure", {"min": 1e6, "max": 1e4, "num": 3}), "sweep.pressure.max"),
    (("sweep.pressure", {"min": 1e4, "max": 1e6}), "sweep.pressure.num"),
    (("sweep.velocity", [-1.0]), "sweep.velocity"),
    (("sweep.velocity", "fast"), "sweep.velocity"),
    (("theory.gamma", 2.0), "theory.gamma"),
    (("numerics.tolerance", 0.0), "numerics.tolerance"),
    (("numerics.solver", "pk"), "numerics.solver"),              # PK with a viscoelastic solid
    (("numerics.fields", ["stress"]), "numerics.fields"),
    (("numerics.enabled", "yes"), "numerics.enabled"),
    (("numerics.petsc", {"contact_step": "sideways"}), "numerics.petsc"),
    (("numerics.petsc", "-contact_step_area 2"), "numerics.petsc"),
    (("numerics.petsc", {"contact_step_area": "x"}), "numerics.petsc"),
    (("output", "results.txt"), "output"),
    (("surface.seeds", {"other": [1], "3e6": [2]}), "surface.seeds.3e6"),      # not one of q1
    (("surface.seeds", {"2e6": [1, 2]}), "surface.seeds"),                     # q1 = 4e6 has none
    (("surface.seeds", {"2e6": [1, 1], "other": [1]}), "surface.seeds.2e6"),   # duplicate seed
    (("surface", ...), "surface"),
]


@pytest.mark.parametrize("change,key", BAD, ids=[f"{c[0]}={c[1]!r}"[:60] for c, _ in BAD])
def test_bad_job_names_key(change, key):
    with pytest.raises(InputError) as err:
        jobs.resolve(_bad(*change), base=ROOT)
    assert err.value.key == key
    assert "\n" not in str(err.value)


def test_unknown_top_level_and_type_errors():
    with pytest.raises(InputError, match="^solver: unknown key"):
        jobs.resolve(dict(GOOD, solver={}), ROOT)
    with pytest.raises(InputError, match="must be a mapping"):
        jobs.resolve(dict(GOOD, material=[1, 2]), ROOT)
    with pytest.raises(InputError, match="YAML mapping"):
        jobs.resolve([1, 2], ROOT)


def test_resolved_defaults_and_grid():
    job = jobs.resolve(copy.deepcopy(GOOD), ROOT)
    assert job.surface.grids() == {repr(2.0e6): 64, repr(4.0e6): 128}    # N = 2 nb q1/q0
    assert job.numerics.tolerance == 1e-8
    assert job.sweep.pressure == pytest.approx((1e4, 1e5, 1e6), rel=1e-12)
    assert job.output == os.path.join(ROOT, "out.h5")
    # a numeric string (YAML reads 1e4 without a dot as a string) is accepted
    job2 = jobs.resolve(_bad("sweep.pressure", ["1e4"]), ROOT)
    assert job2.sweep.pressure == (1e4,)


def test_hrms_normalises_largest_q1():
    j = _bad("surface.C0", ...)
    j["surface"]["hrms"] = 27e-9
    job = jobs.resolve(j, ROOT)
    from vecontact.cases import spectrum_for
    assert spectrum_for(job, 4.0e6).hrms() == pytest.approx(27e-9, rel=1e-12)
    assert spectrum_for(job, 2.0e6).hrms() < 27e-9


def test_physics_hash_ignores_output_only():
    a = jobs.resolve(copy.deepcopy(GOOD), ROOT)
    b = jobs.resolve(_bad("output", "elsewhere.h5"), ROOT)
    c = jobs.resolve(_bad("material.E0", 4.0e6), ROOT)
    assert jobs.physics_hash(a) == jobs.physics_hash(b)
    assert jobs.physics_hash(a) != jobs.physics_hash(c)


def test_fft_planner_is_optional_choice_and_not_physics():
    """numerics.fft_planner: measure or patient; stored only when given (the text of earlier jobs
    stays), and not part of the restart hash (it changes rounding only)."""
    plain = jobs.resolve(copy.deepcopy(GOOD), ROOT)
    patient = jobs.resolve(_bad("numerics.fft_planner", "patient"), ROOT)
    assert plain.numerics.fft_planner is None and "fft_planner" not in plain.to_dict()["numerics"]
    assert patient.numerics.fft_planner == "patient"
    assert patient.to_dict()["numerics"]["fft_planner"] == "patient"
    assert jobs.physics_hash(plain) == jobs.physics_hash(patient)
    for bad in ("exhaustive", "fast", 3):
        with pytest.raises(InputError) as err:
            jobs.resolve(_bad("numerics.fft_planner", bad), ROOT)
        assert err.value.key == "numerics.fft_planner" and "measure, patient" in str(err.value)


def test_seeds_per_q1():
    """A seeds mapping gives the small systems more realisations; the seeds are not physics."""
    from vecontact import cases as sweep
    from vecontact.runner import spectra
    from mpi4py import MPI
    job = jobs.resolve(_bad("surface.seeds", {"other": [1, 2, 3], 4.0e6: [7]}), ROOT)
    assert job.surface.realisations(2.0e6) == (1, 2, 3) and job.surface.realisations(4.0e6) == (7,)
    cs = sweep.expand(job, spectra(job, MPI.COMM_SELF))
    per_q1 = {q1: sorted({c.seed for c in cs if c.q1 == q1}) for q1 in (2.0e6, 4.0e6)}
    assert per_q1 == {2.0e6: [1, 2, 3], 4.0e6: [7]}
    assert len(cs) == (3 + 1) * 2 * 3                   # seeds x velocities x pressures
    # YAML reads 4e6 as a string and 4.0e+6 as a number: both name q1 = 4e6
    for key in ("4e6", 4.0e6):
        assert jobs.resolve(_bad("surface.seeds", {"other": [1], key: [5]}), ROOT).surface.realisations(4.0e6) == (5,)
    flat = jobs.resolve(copy.deepcopy(GOOD), ROOT)
    assert flat.surface.realisations(4.0e6) == (1, 2)
    assert jobs.physics_hash(flat) == jobs.physics_hash(job)   # resuming with more seeds is allowed


@pytest.mark.parametrize("petsc, problem", [
    ({"snes_linesearch_type": "no_such_search"}, "Unable to find requested Line Search type no_such_search"),
    ({"contact_ksp_type": "no_such_krylov"}, "Unable to find requested KSP type no_such_krylov"),
    ({"ksp_rtol": "abc"}, "Input string abc has no numeric value"),
])
def test_cli_value_petsc_refuses_exit_2_one_line_nothing_written(tmp_path, petsc, problem):
    """A PETSc option whose value PETSc refuses stops the run before any case or file, in one line."""
    line = _refused(tmp_path, _bad("numerics", {"enabled": True, "petsc": petsc}), "--no-plot", timeout=300)
    assert line.startswith("vecontact: error: numerics.petsc: PETSc refuses it: ") and problem in line


def test_petsc_options_forms():
    a = jobs.resolve(_bad("numerics.petsc", {"snes_type": "vinewtonrsls", "-ksp_rtol": 1e-3}), ROOT)
    b = jobs.resolve(_bad("numerics.petsc", "-snes_type vinewtonrsls -ksp_rtol 0.001 -snes_monitor"), ROOT)
    assert a.numerics.petsc == {"snes_type": "vinewtonrsls", "ksp_rtol": "0.001"}
    assert b.numerics.petsc == {"snes_type": "vinewtonrsls", "ksp_rtol": "0.001", "snes_monitor": None}


@pytest.mark.parametrize("change,key", BAD[:14], ids=[str(c[0]) for c, _ in BAD[:14]])
def test_cli_bad_job_exit_2_one_line_nothing_written(tmp_path, change, key):
    assert _refused(tmp_path, _bad(*change)).startswith(f"vecontact: error: {key}")


def test_cli_missing_and_malformed_files(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("surface: [unclosed\n")
    for args in (["run", str(tmp_path / "nope.yaml")], ["run", str(bad)], ["plot", str(bad)],
                 ["frobnicate"]):
        proc = subprocess.run([sys.executable, "-m", "vecontact"] + args, capture_output=True,
                              text=True, timeout=60)
        assert proc.returncode == 2, args
        assert len(proc.stderr.strip().splitlines()) == 1 and "Traceback" not in proc.stderr, proc.stderr


def test_shipped_jobs_are_valid():
    for name in ("demo.yaml", "paper.yaml", "paper-small.yaml"):
        path = os.path.join(ROOT, "jobs", name)
        if name == "paper-small.yaml" and not os.path.exists(path):
            continue
        job = jobs.load(path)
        assert job.material.model == "havriliak-negami"
    paper = jobs.load(os.path.join(ROOT, "jobs", "paper.yaml"))
    q0 = paper.surface.q0
    assert [q / q0 for q in paper.surface.q1] == [32, 64, 128, 256]
    assert [paper.surface.grid(q1) for q1 in paper.surface.q1] == [512, 1024, 2048, 4096]
    assert paper.sweep.velocity == (0.01, 0.1, 1.0, 10.0)


def test_the_documented_job_is_valid_as_written(tmp_path):
    """docs/job-file.md's full job (every key, with its comments) loads and validates as written."""
    text = open(os.path.join(ROOT, "docs", "job-file.md")).read()
    (block,) = re.findall(r"```yaml\n(.*?)```", text, re.S)
    (tmp_path / "job.yaml").write_text(block)
    job = jobs.load(str(tmp_path / "job.yaml"))
    assert os.path.basename(job.output) == "example.h5" and not job.numerics.enabled
    assert [job.surface.grid(q1) for q1 in job.surface.q1] == [512, 4096]     # N = 2 null_band q1 / q0
    assert job.sweep.velocity == (0.01, 0.1, 1.0, 10.0)


def test_paper_pressures_span_the_area_range():
    """jobs/paper.yaml: the theory's A/A0 runs from about 0.5 % to about 60 % in every (q1, v)."""
    from vecontact import cases as sweep
    from vecontact.runner import spectra
    from mpi4py import MPI
    job = jobs.load(os.path.join(ROOT, "jobs", "paper.yaml"))
    psds = spectra(job, MPI.COMM_SELF)
    cs = sweep.expand(job, psds)
    rows, _ = sweep.theory(job, psds, cs)
    for q1 in job.surface.q1:
        for v in job.sweep.velocity:
            area = np.array([rows[c.key]["theory_area"] for c in cs
                             if c.q1 == q1 and c.velocity == v and c.seed == 1])
            assert len(area) == 12
            assert area.min() == pytest.approx(0.005, rel=1e-3)
            assert area.max() == pytest.approx(0.6, rel=1e-3)


def test_cli_bad_petsc_option_on_command_line(tmp_path):
    """A solver option of vecontact's own passed on the command line is checked before any solve."""
    job = yaml.safe_load(open(os.path.join(ROOT, "jobs", "demo.yaml")))
    line = _refused(tmp_path, job, "--no-plot", "-contact_step", "sideways")
    assert line.startswith("vecontact: error: numerics.petsc")
