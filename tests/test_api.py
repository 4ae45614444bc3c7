"""The Python API (``import vecontact as vc``): each call against the code it wraps, errors as at
the command line, results readable with and without pandas, the version everywhere the same, and the
docs' snippets running as written."""
import importlib.metadata
import math
import os
import re
import subprocess
import sys
import warnings

import numpy as np
import pytest

import vecontact as vc
from mpi_util import run_mpi
from vecontact.errors import InputError

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ENV = dict(os.environ, PYTHONPATH=ROOT, OMP_NUM_THREADS="1")
Q0 = 2.5e5
MATERIAL = dict(vc.REFERENCE_COMPOUND)
SURFACE = {"spectrum": "self-affine", "q0": Q0, "qr": 4 * Q0, "q1": [8 * Q0], "hurst": 0.8,
           "C0": 1.0616e-28, "null_band": 4, "seeds": [3]}


def small_job(tmp_path, **numerics):
    return vc.make_job(output="out.h5", surface=SURFACE, material=MATERIAL, base=str(tmp_path),
                       sweep={"velocity": [0.01, 1.0], "pressure": [1e5, 3e5]}, numerics=numerics or None)


def test_version_agrees_with_metadata_and_cli():
    assert vc.__version__ == importlib.metadata.version("vecontact")
    proc = subprocess.run([sys.executable, "-m", "vecontact", "--version"], capture_output=True, text=True,
                          env=ENV, timeout=60)
    assert proc.returncode == 0 and proc.stdout.strip() == f"vecontact {vc.__version__}"


def test_import_is_light():
    """``import vecontact`` (and so the command line's start) loads neither MPI nor the API."""
    code = "import sys, vecontact; print('mpi4py' in sys.modules, 'vecontact.api' in sys.modules)"
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=ENV, timeout=60)
    assert proc.stdout.split() == ["False", "False"]
    assert set(vc.__all__) <= set(dir(vc))
    with pytest.raises(AttributeError):
        vc.no_such_name


def test_five_line_script_of_the_docs_runs():
    """docs/api.md opens with the README's five-line script: it runs as written (repository root)."""
    text = open(os.path.join(ROOT, "docs", "api.md")).read()
    script = re.search(r"```python\n(.*?)```", text, re.S).group(1)
    assert len(script.strip().splitlines()) == 5
    assert script in open(os.path.join(ROOT, "README.md")).read()      # the README shows the same script
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, cwd=ROOT, env=ENV,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr
    theory_line, solve_line = proc.stdout.strip().splitlines()
    assert theory_line.startswith("Persson theory") and "A/A0 =" in theory_line
    assert solve_line.startswith("snes: N=96") and "converged=True" in solve_line


def test_theory_is_persson_with_shapes_of_the_inputs():
    from vecontact.physics.modulus import make_modulus
    from vecontact.physics.theory import persson
    psd = vc.self_affine(Q0, 4 * Q0, 16 * Q0, 0.8, C0=1.0616e-28)
    E = vc.modulus(**MATERIAL)
    ref = persson(psd, make_modulus(dict(MATERIAL)), [0.01, 1.0], [1e5, 2e5, 4e5])
    t = vc.theory(psd, E, [0.01, 1.0], [1e5, 2e5, 4e5])
    assert np.array_equal(t.area, ref.area) and np.array_equal(t.mu, ref.mu) and np.array_equal(t.xi, ref.xi)
    assert t.P.shape == ref.P_q.shape and np.array_equal(t.q, ref.q)
    one = vc.theory(psd, E, 1.0, 2e5)
    assert isinstance(one.area, float) and one.area == ref.area[1, 1] and one.mu == ref.mu[1, 1]
    assert one.xi == ref.xi[1] and one.P.shape == ref.q.shape
    assert vc.theory(psd, E, 1.0, [1e5, 2e5]).area.shape == (2,)
    assert vc.theory(psd, E, [0.01, 1.0], 2e5).mu.shape == (2,)
    assert "A/A0 = " in str(one)
    # hrms normalisation as in a job
    assert vc.self_affine(Q0, 4 * Q0, 16 * Q0, 0.8, hrms=20e-9).hrms() == pytest.approx(20e-9, rel=1e-13)


def test_theory_of_a_surface_uses_its_radial_spectrum(tmp_path):
    from mpi4py import MPI
    from vecontact.core.pfft import SlabFFT
    from vecontact.physics.spectrum import Tabulated
    from vecontact.physics.theory import persson
    s = vc.surface(small_job(tmp_path))
    E = vc.modulus(**MATERIAL)
    direct = persson(Tabulated.from_surface(SlabFFT(MPI.COMM_SELF, s.N), s.heights, s.length), E, [0.01], [1e5])
    t = vc.theory(s, E, 0.01, 1e5)
    assert t.area == pytest.approx(direct.area[0, 0], rel=1e-13) and t.mu == pytest.approx(direct.mu[0, 0], rel=1e-13)


def test_surface_of_a_job_is_the_generated_one(tmp_path):
    from mpi4py import MPI
    from vecontact.cases import spectrum_for
    from vecontact.core.pfft import SlabFFT
    from vecontact.core.surface import generate
    job = small_job(tmp_path)
    s = vc.surface(job)
    h = generate(SlabFFT(MPI.COMM_SELF, 64), 2 * math.pi / Q0, spectrum_for(job, 8 * Q0), 3)
    assert s.N == 64 and s.length == 2 * math.pi / Q0 and np.array_equal(s.heights, h)
    assert not np.array_equal(vc.surface(job, q1=2e6, seed=4).heights, h)
    for kwargs, key in (({"q1": 3e6}, "q1"), ({"seed": -1}, "seed")):
        with pytest.raises(InputError) as err:
            vc.surface(job, **kwargs)
        assert err.value.key == key


def test_solve_is_solve_contact(tmp_path):
    """vc.solve builds the serial slab FFT and calls solve_contact: the same numbers."""
    from mpi4py import MPI
    from vecontact.core.pfft import SlabFFT
    from vecontact.solver import solve_contact
    s = vc.surface(small_job(tmp_path))
    E = vc.modulus(**MATERIAL)
    direct = solve_contact(SlabFFT(MPI.COMM_SELF, s.N), s.length, s.heights, E, 0.01, 1e5)
    r = vc.solve(s, E, 0.01, 1e5)
    a = vc.solve(s.heights, E, 0.01, 1e5, length=s.length, tolerance=1e-8, store=("pressure",))
    assert (r.area, r.mu, r.mu_geometric, r.iterations) == (direct.area, direct.mu, direct.mu_geometric,
                                                            direct.iterations)
    assert (a.area, a.mu) == (r.area, r.mu) and a.pressure.shape == (64, 64) and a.gap is None
    assert r.converged and r.N == 64


def test_solve_on_two_ranks(tmp_path):
    """With a communicator the ranks solve together: same result to the solver tolerance."""
    script = tmp_path / "two.py"
    script.write_text(
        "from mpi4py import MPI\nimport vecontact as vc\n"
        f"job = vc.make_job(output='o.h5', surface={SURFACE!r}, material={MATERIAL!r},\n"
        "                  sweep={'velocity': [0.01], 'pressure': [1e5]})\n"
        "s = vc.surface(job)\nE = vc.modulus(**vc.REFERENCE_COMPOUND)\n"
        "r = vc.solve(s, E, 0.01, 1e5, comm=MPI.COMM_WORLD, store=('pressure',))\n"
        "one = vc.solve(s, E, 0.01, 1e5)\n"
        "if MPI.COMM_WORLD.rank == 0:\n"
        "    print(r.area, r.mu, one.area, one.mu, r.pressure.shape[0])\n")
    proc = run_mpi(2, [str(script)], cwd=str(tmp_path))
    area2, mu2, area1, mu1, rows = (float(x) for x in proc.stdout.split())
    assert rows == 32                                             # rank 0's rows of the 64 x 64 grid
    assert abs(area2 - area1) <= 1.0 / 64 ** 2 and mu2 == pytest.approx(mu1, rel=1e-6)


def test_solve_plans_its_grid_with_the_planner_given(tmp_path, monkeypatch):
    """fft_planner reaches the SlabFFT (default measure); patient, planned in its own process so that
    its FFTW wisdom stays out of this one, gives the default's answer to the solver tolerance and
    caches its wisdom under XDG_CACHE_HOME."""
    import vecontact.core.pfft as pfft
    made = []
    real = pfft.SlabFFT
    monkeypatch.setattr(pfft, "SlabFFT", lambda comm, N, **kw: made.append(kw) or real(comm, N))
    s = vc.surface(small_job(tmp_path))
    E = vc.modulus(**MATERIAL)
    made.clear()
    r = vc.solve(s, E, 0.01, 1e5)
    assert made[0] == {"planner": "measure"}           # the solve's grid (then its float32 twin, coarse grids)
    made.clear()
    with pytest.warns(vc.ConvergenceWarning):
        vc.solve(s, E, 0.01, 1e5, fft_planner="patient", max_iterations=1, coarse=False)
    assert made[0] == {"planner": "patient"}
    script = tmp_path / "patient.py"
    script.write_text(
        "import vecontact as vc\n"
        f"job = vc.make_job(output='o.h5', surface={SURFACE!r}, material={MATERIAL!r},\n"
        "                  sweep={'velocity': [0.01], 'pressure': [1e5]})\n"
        "r = vc.solve(vc.surface(job), vc.modulus(**vc.REFERENCE_COMPOUND), 0.01, 1e5, fft_planner='patient')\n"
        "print(r.area, r.mu, r.converged)\n")
    env = dict(ENV, XDG_CACHE_HOME=str(tmp_path / "cache"))
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, env=env, cwd=tmp_path,
                         timeout=300)
    assert out.returncode == 0, out.stderr
    area, mu, converged = out.stdout.split()
    # same contact set up to a point that sits on the tolerance; mu to the solver tolerance
    assert converged == "True" and abs(float(area) - r.area) <= 1.0 / s.N ** 2
    assert float(mu) == pytest.approx(r.mu, rel=1e-6)
    assert list((tmp_path / "cache" / "vecontact").glob("fftw-wisdom-*.pkl"))


def test_errors_name_the_key_in_one_line(tmp_path):
    E = vc.modulus(**MATERIAL)
    s = vc.surface(small_job(tmp_path))
    psd = vc.self_affine(Q0, 4 * Q0, 16 * Q0, 0.8, C0=1e-28)
    cases = [
        (lambda: vc.modulus("havriliak-negami", E0=3e6), "material.Einf"),
        (lambda: vc.modulus("maxwell"), "material.model"),
        (lambda: vc.theory(psd, E, -1.0, 1e5), "velocity"),
        (lambda: vc.theory(psd, E, 0.01, [1e5, 0.0]), "pressure"),
        (lambda: vc.theory(psd, E, 0.01, 1e5, gamma=2), "theory.gamma"),
        (lambda: vc.theory(42, E, 0.01, 1e5), "psd"),
        (lambda: vc.solve(s, E, 0.01, 1e5, colour="red"), "colour"),
        (lambda: vc.solve(s.heights, E, 0.01, 1e5), "length"),
        (lambda: vc.solve(s.heights[:, :10], E, 0.01, 1e5, length=1e-5), "surface"),
        (lambda: vc.solve(s, E, 0.01, -1e5), "pressure"),
        (lambda: vc.solve(s, E, 0.01, 1e5, method="pk"), "options"),       # pk needs an elastic solid
        (lambda: vc.solve(s, E, 0.01, 1e5, fft_planner="exhaustive"), "fft_planner"),
        (lambda: vc.self_affine(Q0, 4 * Q0, 2 * Q0, 0.8, C0=1e-28), "surface.qr"),
        (lambda: vc.run({"surface": {}}), "job"),
        (lambda: vc.load_job(tmp_path / "none.yaml"), "job"),
        (lambda: vc.make_job(output="o.h5", surface=dict(SURFACE, hurst=1.5), material=MATERIAL,
                             sweep={"velocity": [1], "pressure": [1e5]}), "surface.hurst"),
        (lambda: vc.read_psd(tmp_path / "none.csv"), "surface.file"),
        (lambda: vc.read_topography(tmp_path / "h.npy"), "length"),
        (lambda: vc.read_results(tmp_path / "none.h5"), "results"),
    ]
    for call, key in cases:
        with pytest.raises(InputError) as err:
            call()
        assert err.value.key == key and "\n" not in str(err.value), (key, str(err.value))


def test_not_converged_warns(tmp_path):
    s = vc.surface(small_job(tmp_path))
    with pytest.warns(vc.ConvergenceWarning, match="not converged"):
        r = vc.solve(s, vc.modulus(**MATERIAL), 1.0, 1e5, max_iterations=1, coarse=False)
    assert not r.converged


def test_coverage_warning_from_theory(tmp_path):
    omega = np.geomspace(1.0, 1e6, 30)
    E = vc.modulus(**MATERIAL)(omega)
    path = tmp_path / "dma.txt"
    np.savetxt(path, np.c_[omega, E.real, E.imag])
    table = vc.modulus("table", file=str(path))
    psd = vc.self_affine(Q0, 4 * Q0, 16 * Q0, 0.8, C0=1e-28)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        vc.theory(psd, table, 1e-3, 1e5)                          # q v inside the table: silent
    with pytest.warns(vc.InputWarning, match=r"modulus: .* v = 1 m/s: q > 1e\+06 1/m above omega_max"):
        vc.theory(psd, table, 1.0, 1e5)


def test_run_and_read_results_with_and_without_pandas(tmp_path, monkeypatch):
    job = small_job(tmp_path, enabled=True)
    assert vc.run(job) == str(tmp_path / "out.h5")
    cases = vc.read_results(job.output, as_frame=False)
    assert cases.dtype.names[:4] == ("q1", "seed", "velocity", "pressure") and len(cases) == 4
    assert np.all(cases["status"] == 1)
    s = vc.surface(job)
    r = vc.solve(s, vc.modulus(**MATERIAL), 1.0, 3e5)
    row = cases[(cases["velocity"] == 1.0) & (cases["pressure"] == 3e5)][0]
    assert abs(row["area"] - r.area) <= 1.0 / 64 ** 2 and row["mu"] == pytest.approx(r.mu, rel=1e-6)
    pd = pytest.importorskip("pandas")
    df = vc.read_results(job.output)
    assert isinstance(df, pd.DataFrame) and df.attrs["units"]["pressure"] == "Pa"
    assert np.array_equal(df["mu"].to_numpy(), cases["mu"])
    monkeypatch.setitem(sys.modules, "pandas", None)             # pandas not installed
    assert isinstance(vc.read_results(job.output), np.ndarray)
    with pytest.raises(InputError, match="pandas is not installed"):
        vc.read_results(job.output, as_frame=True)
    monkeypatch.undo()
    paths = vc.plot_results(job.output, str(tmp_path / "figs"))
    names = sorted(os.path.basename(p) for p in paths)      # no maps file: every figure but Fig. 3
    assert names == ["fig1_spectrum.png", "fig2_friction.png", "fig4_area.png", "fig5_master.png",
                     "gamma_sensitivity.png", "morphology.png", "morphology_vs_v.png", "theory_error.png"]
    assert all(os.path.getsize(p) > 0 for p in paths)


def test_the_docs_result_reading_snippets_run_as_written(tmp_path):
    """Every ``python`` block of README.md, docs/reading-results.md and docs/results-format.md that reads
    results/demo.h5 runs as written (cwd holding a small job's results under that name)."""
    pytest.importorskip("pandas")
    job = small_job(tmp_path, enabled=True)
    vc.run(job)
    os.makedirs(tmp_path / "results")
    os.symlink(job.output, tmp_path / "results" / "demo.h5")
    blocks = []
    for doc in ("README.md", os.path.join("docs", "reading-results.md"), os.path.join("docs", "results-format.md")):
        text = open(os.path.join(ROOT, doc)).read()
        blocks += [(doc, b) for b in re.findall(r"```python\n(.*?)```", text, re.S) if "results/demo.h5" in b]
    assert len(blocks) >= 5, [d for d, _ in blocks]
    for doc, block in blocks:
        proc = subprocess.run([sys.executable, "-c", block], capture_output=True, text=True, cwd=tmp_path,
                              env=ENV, timeout=120)
        assert proc.returncode == 0, f"{doc}:\n{block}\n{proc.stderr}"


def test_load_job_and_make_job_agree(tmp_path, monkeypatch):
    import yaml
    raw = {"output": "out.h5", "surface": SURFACE, "material": MATERIAL,
           "sweep": {"velocity": [0.01], "pressure": [1e5]}}
    (tmp_path / "job.yaml").write_text(yaml.safe_dump(raw))
    monkeypatch.chdir(tmp_path)
    a = vc.load_job("job.yaml")
    b = vc.make_job(**{k: v for k, v in raw.items()})
    assert a == b and isinstance(a, vc.Job) and a.output == str(tmp_path / "out.h5")
    assert a.to_dict() == b.to_dict() and vc.run(a.to_dict()) == a.output        # the resolved dict is a job too
