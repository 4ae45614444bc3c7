"""Measured inputs: C(q) tables (2-D and line-scan), instrument topography files, DMA master curves.

Each is checked against the analytic input it was made from, through the job file, the command
line (exit 2 and one line for bad input, nothing written) and the solver.
"""
import copy
import hashlib
import math
import os
import subprocess
import sys
import zipfile

import numpy as np
import pytest
import yaml

from mpi_util import mpiexec
from vecontact import job as jobs
from vecontact.errors import InputError
from vecontact.io.psd import read_psd
from vecontact.io.tables import read_columns
from vecontact.jobtypes import fft_size
from vecontact.physics.modulus import HavriliakNegami, Table, coverage
from vecontact.physics.spectrum import SelfAffine, Tabulated, isotropic_from_line, line_psd
from vecontact.physics.theory import persson

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
ENV = dict(os.environ, PYTHONPATH=ROOT, OMP_NUM_THREADS="1")
Q0 = 2.5e5
PAPER = SelfAffine(Q0, 4 * Q0, 256 * Q0, 0.8, 1.0616e-28)      # docs/conventions.md §2
HN = HavriliakNegami(3e6, 3e9, 0.5, 0.5, 1e-10)                  # the reference compound
MATERIAL = {"model": "havriliak-negami", "E0": 3e6, "Einf": 3e9, "alpha": 0.5, "beta": 0.5, "tau": 1e-10}


def write_psd(path, q, C, header="q (1/m),C (m^4)\n"):
    with open(path, "w") as f:
        f.write(header)
        for a, b in zip(q, C):
            f.write(f"{a:.17g},{b:.17g}\n")
    return path


def self_affine_rows(spectrum, n):
    """n log-spaced rows on each smooth piece of a self-affine spectrum, its kinks included: the
    log-log interpolant of these rows is the spectrum itself (a piecewise power law)."""
    kinks = spectrum.breakpoints
    q = np.unique(np.concatenate([np.geomspace(a, b, n) for a, b in zip(kinks[:-1], kinks[1:])]))
    return q, spectrum(q)


def cli(*args, cwd, timeout=300):
    return subprocess.run([sys.executable, "-m", "vecontact", *args], capture_output=True, text=True,
                          cwd=cwd, env=ENV, timeout=timeout)


def assert_one_line_error(proc, key):
    assert proc.returncode == 2, proc.stderr + proc.stdout
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"vecontact: error: {key}"), proc.stderr
    assert "Traceback" not in proc.stderr + proc.stdout


# ------------------------------------------------------------------------------------------------
# tables
def test_table_formats(tmp_path):
    rows = np.array([[1.0, 2.0, 3.0], [4.0, 5.5, 6.0]])
    p = tmp_path / "t.txt"
    for sep in (",", ";", "\t", "  "):
        body = "\n".join(sep.join(f"{x:g}" for x in r) + "  # note" for r in rows)
        p.write_text(f"# comment\n\na{sep}b{sep}c\n{body}\n")
        assert np.array_equal(read_columns(p, "k", ("x", "y", "z")), rows), sep
    p = tmp_path / "wide.csv"
    p.write_text("f,T,E1,E2\n1,20,3,4\n2,20,5,6\n")
    assert np.array_equal(read_columns(p, "k", ("f", "a", "b"), ["f", 2, "E2"]), [[1, 3, 4], [2, 5, 6]])
    for columns, fragment in ((["f", "E9", 3], "'E9'"), ([0, 1], "must list 3"), ([0, 1, 7], "column 7")):
        with pytest.raises(InputError, match=fragment) as err:
            read_columns(p, "material.file", ("f", "a", "b"), columns)
        assert err.value.key == "material.file"
    p.write_text("1,2\n3\n")
    with pytest.raises(InputError, match="line 2: expected 2 columns"):
        read_columns(p, "k", ("q", "C"))
    p.write_text("q,C\n1,2\nx,3\n")
    with pytest.raises(InputError, match="line 3: 'x' is not a number"):
        read_columns(p, "k", ("q", "C"))


# ------------------------------------------------------------------------------------------------
# measured 2-D spectra
def test_theory_from_a_psd_table_equals_the_analytic_spectrum(tmp_path):
    """The table of a self-affine spectrum (rows on its kinks, 17 digits) is that spectrum: the
    theory agrees to the quadrature's rounding (the table's panels are split at every row, the
    analytic ones at the kinks only; both are converged far below 1e-9)."""
    spectrum = SelfAffine(Q0, 4 * Q0, 64 * Q0, 0.8, 1.0616e-28)
    table = read_psd(write_psd(tmp_path / "C.csv", *self_affine_rows(spectrum, 12)))
    assert table.hrms() == pytest.approx(spectrum.hrms(), rel=1e-13)
    assert table.slope2() == pytest.approx(spectrum.slope2(), rel=1e-13)
    v, p = [1e-3, 0.1, 10.0], [3e4, 1e5, 1e6]
    a, b = persson(spectrum, HN, v, p), persson(table, HN, v, p)
    for name in ("area", "mu", "xi"):
        assert np.allclose(getattr(b, name), getattr(a, name), rtol=1e-9, atol=0), name


def test_psd_job_theory_matches_the_self_affine_job(tmp_path):
    """Through the job and the command line: a theory-only job on the table writes the same
    theory columns as the self-affine job it was sampled from."""
    spectrum = SelfAffine(Q0, 4 * Q0, 32 * Q0, 0.8, 1.0616e-28)
    write_psd(tmp_path / "C.csv", *self_affine_rows(spectrum, 10))
    sweep = {"velocity": [0.01, 1.0], "pressure": [1e5, 1e6]}
    jobs_ = {"psd": {"spectrum": "psd", "file": "C.csv"},
             "sa": {"spectrum": "self-affine", "q0": Q0, "qr": 4 * Q0, "q1": [32 * Q0], "hurst": 0.8,
                    "C0": 1.0616e-28}}
    tables = {}
    for name, surface in jobs_.items():
        (tmp_path / f"{name}.yaml").write_text(yaml.safe_dump(
            {"output": f"{name}.h5", "surface": surface, "material": MATERIAL, "sweep": sweep}))
        proc = cli("run", f"{name}.yaml", "--no-plot", "--quiet", cwd=tmp_path)
        assert proc.returncode == 0, proc.stderr
        from vecontact.io.results import read_cases
        tables[name] = read_cases(str(tmp_path / f"{name}.h5"))
    a, b = tables["sa"], tables["psd"]
    assert np.allclose(b["q1"], a["q1"], rtol=1e-12)
    for col in ("theory_area", "theory_mu", "xi", "slope_rms"):
        assert np.allclose(b[col], a[col], rtol=1e-9, atol=0), col


def test_psd_job_system_size_and_grid(tmp_path):
    spectrum = SelfAffine(Q0, 4 * Q0, 32 * Q0, 0.8, 1.0616e-28)
    write_psd(tmp_path / "C.csv", *self_affine_rows(spectrum, 6))
    raw = {"output": "o.h5", "surface": {"spectrum": "psd", "file": "C.csv", "null_band": 2},
           "material": MATERIAL, "sweep": {"velocity": [0.01], "pressure": [1e5]}}
    job = jobs.resolve(copy.deepcopy(raw), str(tmp_path))
    s = job.surface
    assert s.length == pytest.approx(2 * math.pi / Q0, rel=1e-15) and s.q1 == (32 * Q0,)
    assert s.grids() == {repr(32 * Q0): 128}                      # 2 null_band q1 / q0 = 128
    raw["surface"].update(q1=[10 * Q0], length=2 * math.pi / (2 * Q0))
    job = jobs.resolve(copy.deepcopy(raw), str(tmp_path))
    assert job.surface.grids() == {repr(10 * Q0): 20}             # 2 * 2 * 10 / 2 = 20 -> 5 * 4
    assert [fft_size(n) for n in (3, 4, 7, 100, 129, 1000, 1025)] == [4, 4, 8, 128, 160, 1024, 1280]
    from vecontact.runner import spectra
    from mpi4py import MPI
    band = spectra(job, MPI.COMM_SELF)[10 * Q0]                   # the system's band of the table
    assert (band.q_min, band.q_max) == pytest.approx((2 * Q0, 10 * Q0), rel=1e-12)
    assert band(3 * Q0) == pytest.approx(spectrum(3 * Q0), rel=1e-12) and band(1.5 * Q0) == 0
    for change, key in (({"q1": [64 * Q0]}, "surface.q1"), ({"dimension": 3}, "surface.dimension"),
                        ({"columns": [0]}, "surface.columns"), ({"colour": 1}, "surface.colour")):
        bad = copy.deepcopy(raw)
        bad["surface"].update(change)
        with pytest.raises(InputError) as err:
            jobs.resolve(bad, str(tmp_path))
        assert err.value.key == key


def test_psd_job_surfaces_are_synthesised_from_the_table(tmp_path):
    """Numerics on a table: |h_q|^2 = C(|q|) (2 pi / L)^2 on every mode of the band (fixed
    amplitudes), to rounding."""
    import vecontact as vc
    from vecontact.core.pfft import SlabFFT
    from mpi4py import MPI
    spectrum = SelfAffine(Q0, 4 * Q0, 16 * Q0, 0.8, 1.0616e-28)
    write_psd(tmp_path / "C.csv", *self_affine_rows(spectrum, 6))
    job = vc.make_job(output="o.h5", surface={"spectrum": "psd", "file": "C.csv", "null_band": 2, "seeds": [4]},
                      material=MATERIAL, sweep={"velocity": [0.01], "pressure": [1e5]}, base=str(tmp_path))
    s = vc.surface(job)
    assert s.N == 64 and s.length == pytest.approx(2 * math.pi / Q0, rel=1e-15) and s.info["seed"] == 4
    fft = SlabFFT(MPI.COMM_SELF, s.N)
    hq = fft.forward(s.heights) / s.N ** 2
    q = fft.wavevectors(s.length)[2]
    expected = spectrum(q) * (2 * math.pi / s.length) ** 2
    assert np.allclose(np.abs(hq) ** 2, expected, rtol=1e-9, atol=1e-12 * expected.max())


BAD_TABLES = [
    ("non-monotonic", lambda q, C: (q[[0, 2, 1, 3, 4, 5, 6, 7, 8, 9]], C), "must increase strictly"),
    ("negative", lambda q, C: (q, np.where(np.arange(q.size) == 4, -C, C)), "negative C"),
    ("zero", lambda q, C: (q, np.where(np.arange(q.size) == 4, 0.0, C)), "C = 0"),
    ("few", lambda q, C: (q[:5], C[:5]), "at least 8"),
    ("q in 1/um", lambda q, C: (q * 1e-6, C), "1/m"),
    ("C in um^4", lambda q, C: (q, C * 1e24), "h_rms"),
    ("C in nm^4", lambda q, C: (q, C * 1e36), "h_rms"),
    ("q in 1/nm", lambda q, C: (q * 1e-9, C), "1/m"),
]


@pytest.mark.parametrize("name, change, fragment", BAD_TABLES, ids=[b[0] for b in BAD_TABLES])
def test_bad_psd_tables(tmp_path, name, change, fragment):
    q = np.geomspace(Q0, 32 * Q0, 10)
    path = write_psd(tmp_path / "C.csv", *change(q, SelfAffine(Q0, 4 * Q0, 32 * Q0, 0.8, 1.0616e-28)(q)))
    with pytest.raises(InputError) as err:
        read_psd(path)
    assert err.value.key == "surface.file" and fragment in err.value.problem, err.value.problem
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("name, change, fragment", [BAD_TABLES[i] for i in (0, 1, 5)],
                         ids=[BAD_TABLES[i][0] for i in (0, 1, 5)])
def test_cli_bad_psd_table_exit_2_one_line_nothing_written(tmp_path, name, change, fragment):
    q = np.geomspace(Q0, 32 * Q0, 10)
    write_psd(tmp_path / "C.csv", *change(q, SelfAffine(Q0, 4 * Q0, 32 * Q0, 0.8, 1.0616e-28)(q)))
    (tmp_path / "job.yaml").write_text(yaml.safe_dump({
        "output": "out.h5", "surface": {"spectrum": "psd", "file": "C.csv"}, "material": MATERIAL,
        "sweep": {"velocity": [0.01], "pressure": [1e5]}, "numerics": {"enabled": True}}))
    proc = cli("run", "job.yaml", cwd=tmp_path)
    assert_one_line_error(proc, "surface.file")
    assert fragment in proc.stderr
    assert sorted(os.listdir(tmp_path)) == ["C.csv", "job.yaml"]


# ------------------------------------------------------------------------------------------------
# 1-D line-scan spectra
def test_line_psd_of_a_disk_is_analytic():
    """C = C0 for |q| <= q1 gives C1D(qx) = 2 C0 sqrt(q1^2 - qx^2) exactly."""
    disk = SelfAffine(1e-9 * Q0, Q0, Q0, 0.8, 2.0)       # qr = q1: flat up to q1, q0 negligible
    qx = np.linspace(0.01, 0.999, 40) * Q0
    assert np.allclose(line_psd(disk, qx), 2 * 2.0 * np.sqrt(Q0 ** 2 - qx ** 2), rtol=1e-12, atol=0)


def test_abel_inversion_of_a_power_law_is_exact():
    """C = A q^-2(1+H) <-> C1D = A c_H q^-(1+2H), c_H = sqrt(pi) Gamma(H + 1/2) / Gamma(H + 1); the
    table is a power law and so is its fitted tail: the inversion is exact up to the quadrature."""
    H = 0.8
    c = math.sqrt(math.pi) * math.gamma(H + 0.5) / math.gamma(H + 1)
    q = np.geomspace(1e5, 1e8, 60)
    C2 = isotropic_from_line(q, 3.0 * c * q ** -(1 + 2 * H))
    assert np.allclose(C2, 3.0 * q ** (-2 * (1 + H)), rtol=1e-12, atol=0)
    # and the forward transform of the (truncated far away) power law gives C1D back
    wide = Tabulated(np.geomspace(1e3, 1e12, 50), 3.0 * np.geomspace(1e3, 1e12, 50) ** (-2 * (1 + H)))
    assert np.allclose(line_psd(wide, q), 3.0 * c * q ** -(1 + 2 * H), rtol=1e-6, atol=0)


def test_line_scan_round_trip_of_the_paper_spectrum(tmp_path):
    """C2D (paper) -> C1D (line_psd) -> file -> read_psd(dimension=1) -> C2D.

    The table ends at q1 (C1D -> 0 there like sqrt(q1 - q)), so its fitted tail is only a model:
    compare up to q1/2. Log-log interpolation of C1D is second order where C1D is smooth, first
    order next to the roll-off kink qr (C1D' has an inverse-square-root singularity there):
    the errors must fall on refinement (x2 rows: at least x1.7 smooth, x1.7 at the kink), and at
    400 rows stay below 3e-4 above qr, 2e-3 below it, 1.5e-2 at it, with h_rms within 5e-4.
    """
    errors = {}
    for n in (200, 400):
        q = np.append(np.geomspace(Q0, 256 * Q0, n)[:-1], 256 * Q0 * (1 - 1e-6))
        path = write_psd(tmp_path / f"line{n}.csv", q, line_psd(PAPER, q), header="q,C1D\n")
        psd = read_psd(path, dimension=1)
        err = np.abs(psd.C / PAPER(q) - 1)
        errors[n] = {"below": err[q <= 3.5 * Q0].max(), "kink": err[(q > 3.5 * Q0) & (q < 4.5 * Q0)].max(),
                     "above": err[(q >= 4.5 * Q0) & (q <= 128 * Q0)].max(),
                     "hrms": abs(psd.hrms() / PAPER.hrms() - 1)}
    e, f = errors[400], errors[200]
    assert e["above"] < 3e-4 and e["below"] < 2e-3 and e["kink"] < 1.5e-2 and e["hrms"] < 5e-4, e
    assert all(f[k] / e[k] > 1.7 for k in ("above", "below", "kink", "hrms")), (f, e)


def test_line_scan_table_that_rises_is_refused(tmp_path):
    q = np.geomspace(Q0, 64 * Q0, 20)
    C1 = line_psd(PAPER, q)
    C1[8] *= 30                                               # a spike: C1D rises, C2D < 0 before it
    with pytest.raises(InputError, match="<= 0 at"):
        read_psd(write_psd(tmp_path / "l.csv", q, C1), dimension=1)
    with pytest.raises(InputError, match="does not decay"):
        read_psd(write_psd(tmp_path / "flat.csv", q, np.full(q.size, 1e-20)), dimension=1)


# ------------------------------------------------------------------------------------------------
# DMA master curves
def write_dma(path, f_hz, E, scale=1e-6):
    with open(path, "w") as out:
        out.write("# DMA export\nfrequency (Hz),temperature (C),E' (MPa),E'' (MPa),tan delta\n")
        for fi, ei in zip(f_hz, E):
            out.write(f"{fi:.17g},20,{ei.real * scale:.17g},{ei.imag * scale:.17g},{ei.imag / ei.real:.6g}\n")
    return path


def test_dma_csv_in_hz_and_mpa_with_wlf_and_vertical_shift(tmp_path):
    f = np.geomspace(1e-3, 1e12, 200)
    path = write_dma(tmp_path / "dma.csv", f, HN(2 * np.pi * f))
    wlf = {"C1": 8.86, "C2": 101.6, "T_ref": 20.0, "T": 35.0}
    material = {"model": "table", "file": "dma.csv", "frequency_unit": "Hz", "modulus_unit": "MPa",
                "columns": ["frequency (Hz)", "E' (MPa)", "E'' (MPa)"], "wlf": wlf, "vertical_shift": 1.05}
    job = jobs.resolve({"output": "o.h5", "surface": {"spectrum": "self-affine", "q0": Q0, "q1": [4 * Q0],
                                                      "hurst": 0.8, "C0": 1e-28},
                        "material": material, "sweep": {"velocity": [0.01], "pressure": [1e5]}}, str(tmp_path))
    E = job.material.modulus()
    aT = 10 ** (-8.86 * 15 / 116.6)
    assert isinstance(E, Table) and E.aT == pytest.approx(aT, rel=1e-14)
    # at the rows (omega = 2 pi f / aT at temperature T): exact up to the 17-digit rounding
    w = 2 * np.pi * f / aT
    assert np.allclose(E(w), 1.05 * HN(aT * w), rtol=1e-12, atol=0)
    # between rows: log-log interpolation, error <= h^2/8 max|d^2 ln E/d(ln w)^2| = 5e-4 (see test_modulus)
    mid = np.sqrt(w[1:] * w[:-1])
    assert np.abs(E(mid) / (1.05 * HN(aT * mid)) - 1).max() < 1e-3
    assert (E.E0, E.Einf) == pytest.approx((1.05 * HN(2 * np.pi * 1e-3).real, 1.05 * HN(2 * np.pi * 1e12).real),
                                           rel=1e-12)


def test_dma_table_errors(tmp_path):
    f = np.geomspace(1e-3, 1e9, 30)
    write_dma(tmp_path / "dma.csv", f, HN(2 * np.pi * f))
    base = {"model": "table", "file": "dma.csv", "columns": [0, 2, 3], "frequency_unit": "Hz",
            "modulus_unit": "MPa"}
    for change, key, fragment in (({"modulus_unit": "Pa"}, "material.file", "modulus_unit"),
                                  ({"frequency_unit": "rpm"}, "material.frequency_unit", "Hz"),
                                  ({"columns": [0, 2, "E3"]}, "material.file", "'E3'"),
                                  ({"columns": [0, 2]}, "material.columns", "3 columns"),
                                  ({"vertical_shift": 0}, "material.vertical_shift", "> 0"),
                                  ({"columns": None}, "material.file", "expected 3 columns")):
        with pytest.raises(InputError) as err:
            jobs._material({"material": dict(base, **change)}, str(tmp_path))
        assert err.value.key == key and fragment in err.value.problem, err.value


def test_coverage_names_velocities_and_wavevectors():
    omega = np.geomspace(1.0, 1e6, 40)
    table = Table(omega, HN(omega).real, HN(omega).imag)
    assert coverage(table, 1e5, 1e7, [1e-4, 1e-2]) is None              # q v in 10 .. 1e5
    text = coverage(table, 1e5, 1e7, [1e-6, 1e-2, 1.0])
    assert "v = 1e-06 m/s: q < 1e+06 1/m below omega_min" in text
    assert "v = 1 m/s: q > 1e+06 1/m above omega_max" in text and "0.01" not in text.split("needs")[1]
    assert "E' held at E'(omega_min)" in text and "\n" not in text
    assert coverage(HN, 1e5, 1e7, [1e3]) is None                        # analytic: every frequency


def test_cli_warns_when_the_table_does_not_cover_q_v(tmp_path):
    omega = np.geomspace(1.0, 1e6, 40)
    with open(tmp_path / "dma.txt", "w") as out:
        for w, e in zip(omega, HN(omega)):
            out.write(f"{w:.17g} {e.real:.17g} {e.imag:.17g}\n")
    (tmp_path / "job.yaml").write_text(yaml.safe_dump({
        "output": "out.h5", "material": {"model": "table", "file": "dma.txt"},
        "surface": {"spectrum": "self-affine", "q0": Q0, "qr": 4 * Q0, "q1": [8 * Q0], "hurst": 0.8, "C0": 1e-28},
        "sweep": {"velocity": [1e-3, 1.0], "pressure": [1e5]}}))
    proc = cli("run", "job.yaml", "--no-plot", "--quiet", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("vecontact: warning: material.file: the master curve"), lines
    assert "v = 1 m/s: q > 1e+06 1/m above omega_max" in lines[0] and "0.001" not in lines[0]


# ------------------------------------------------------------------------------------------------
# instrument topography files
def write_x3p(path, heights, dx, dy):
    """An ISO 25178-72 X3P file written by hand (zip: main.xml + bindata/data.bin), with 32-bit
    integer heights h = raw * Increment + Offset (m). Returns the heights as stored."""
    lo, hi = float(heights.min()), float(heights.max())
    inc = (hi - lo) / (2 ** 32 - 2)
    off = lo + 2 ** 31 * inc
    raw = np.round((heights - off) / inc).astype("<i4")
    data = raw.T.tobytes()                                    # x runs fastest
    nx, ny = heights.shape
    xml = f"""<?xml version="1.0" encoding="UTF-8"?>
<p:ISO5436_2 xmlns:p="http://www.opengps.eu/2008/ISO5436_2">
<Record1><Revision>ISO5436 - 2000</Revision><FeatureType>SUR</FeatureType><Axes>
<CX><AxisType>I</AxisType><DataType>D</DataType><Increment>{dx!r}</Increment><Offset>0</Offset></CX>
<CY><AxisType>I</AxisType><DataType>D</DataType><Increment>{dy!r}</Increment><Offset>0</Offset></CY>
<CZ><AxisType>A</AxisType><DataType>L</DataType><Increment>{inc!r}</Increment><Offset>{off!r}</Offset></CZ>
</Axes></Record1>
<Record3><MatrixDimension><SizeX>{nx}</SizeX><SizeY>{ny}</SizeY><SizeZ>1</SizeZ></MatrixDimension>
<DataLink><PointDataLink>bindata/data.bin</PointDataLink>
<MD5ChecksumPointData>{hashlib.md5(data).hexdigest().upper()}</MD5ChecksumPointData></DataLink></Record3>
<Record4><ChecksumFile>md5checksum.hex</ChecksumFile></Record4>
</p:ISO5436_2>
"""
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("main.xml", xml)
        z.writestr("bindata/data.bin", data)
        z.writestr("md5checksum.hex", hashlib.md5(xml.encode()).hexdigest().upper() + " *main.xml\n")
    return raw * inc + off


def scan(nx=40, ny=30, dx=0.4e-6, seed=2):
    """A tilted, offset, non-square scan (heights in m) and its pixel size."""
    from mpi4py import MPI
    from vecontact.core.pfft import SlabFFT
    from vecontact.core.surface import generate
    L = 64 * dx
    h = generate(SlabFFT(MPI.COMM_SELF, 64), L, SelfAffine(2 * np.pi / L, 8 * np.pi / L, 32 * np.pi / L, 0.8,
                                                             1e-28), seed)[:nx, :ny]
    x, y = np.arange(nx)[:, None] * dx, np.arange(ny)[None, :] * dx
    return h + 3e-3 * x - 1e-3 * y + 4e-6, dx


def prepared(h):
    """What vecontact.io.topography must make of the non-periodic scan h: central square crop,
    least-squares plane removed (by lstsq here), reflected."""
    nx, ny = h.shape
    n = min(nx, ny) // 2 * 2
    i, j = (nx - n) // 2, (ny - n) // 2
    c = h[i:i + n, j:j + n]
    X, Y = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    A = np.column_stack([np.ones(n * n), X.ravel(), Y.ravel()])
    c = c - (A @ np.linalg.lstsq(A, c.ravel(), rcond=None)[0]).reshape(n, n)
    return np.block([[c, c[:, ::-1]], [c[::-1, :], c[::-1, ::-1]]])


def test_x3p_is_cropped_detrended_and_reflected(tmp_path):
    pytest.importorskip("SurfaceTopography")
    from vecontact.io.topography import read_topography
    h, dx = scan()
    stored = write_x3p(tmp_path / "scan.x3p", h, dx, dx)
    got, L, info = read_topography(tmp_path / "scan.x3p")
    assert got.shape == (60, 60) and L == pytest.approx(60 * dx, rel=1e-14)
    # the int32 heights resolve 5e-8 m / 2^32 ~ 1e-17 m; the plane fit is exact to rounding
    assert np.abs(got - prepared(stored)).max() < 1e-18
    assert abs(got.mean()) < 1e-20 and info["source_grid"] == [40, 30] and info["crop"] == [5, 0, 30]
    assert "reflected to 60 x 60" in info["processing"] and info["format"].startswith("XML 3D")


def test_periodic_file_in_micrometres_is_used_as_it_is(tmp_path):
    """A NetCDF file (SurfaceTopography's writer) marked periodic, lateral sizes and heights in um."""
    ST = pytest.importorskip("SurfaceTopography")
    from vecontact.io.topography import read_topography
    h, dx = scan(32, 32)
    ST.Topography(h * 1e6, (32 * dx * 1e6, 32 * dx * 1e6), unit="um", periodic=True).to_netcdf(
        str(tmp_path / "p.nc"))
    got, L, info = read_topography(tmp_path / "p.nc")
    X = np.arange(32)[:, None] - 15.5
    Y = np.arange(32)[None, :] - 15.5
    flat = h - h.mean() - X * (X * h).sum() / (32 * (X ** 2).sum()) - Y * (Y * h).sum() / (32 * (Y ** 2).sum())
    assert got.shape == (32, 32) and L == pytest.approx(32 * dx, rel=1e-12)
    assert np.allclose(got, flat, rtol=0, atol=1e-12 * np.abs(h).max())
    assert info["periodic_in_file"] and "periodic as read" in info["processing"]


def test_bad_topography_files(tmp_path):
    pytest.importorskip("SurfaceTopography")
    from vecontact.io.topography import read_topography
    h, dx = scan()
    write_x3p(tmp_path / "aniso.x3p", h, dx, 1.5 * dx)
    write_x3p(tmp_path / "tiny.x3p", h[:10, :12], dx, dx)
    (tmp_path / "junk.sur").write_bytes(b"not a topography\x00\x01" * 20)
    for name, fragment in (("aniso.x3p", "not square"), ("tiny.x3p", "at least 16"), ("junk.sur", "not a topography"),
                           ("none.x3p", "file not found")):
        with pytest.raises(InputError, match=fragment) as err:
            read_topography(tmp_path / name)
        assert err.value.key == "surface.file" and "\n" not in str(err.value)
    raw = {"output": "o.h5", "surface": {"spectrum": "file", "file": "aniso.x3p", "length": 1e-5},
           "material": MATERIAL, "sweep": {"velocity": [0.01], "pressure": [1e5]}}
    with pytest.raises(InputError) as err:
        jobs.resolve(raw, str(tmp_path))
    assert err.value.key == "surface.length"


def test_without_surfacetopography_the_error_names_the_extra(tmp_path):
    h, dx = scan()
    write_x3p(tmp_path / "scan.x3p", h, dx, dx)
    (tmp_path / "job.yaml").write_text(yaml.safe_dump({
        "output": "out.h5", "surface": {"spectrum": "file", "file": "scan.x3p"}, "material": MATERIAL,
        "sweep": {"velocity": [0.01], "pressure": [1e5]}}))
    block = "import sys; sys.modules['SurfaceTopography'] = None; "
    proc = subprocess.run([sys.executable, "-c", block + "from vecontact.cli import main; sys.exit(main())",
                           "run", "job.yaml"], capture_output=True, text=True, cwd=tmp_path, env=ENV, timeout=120)
    assert_one_line_error(proc, "surface.file")
    assert "pip install 'vecontact[topography]'" in proc.stderr
    assert sorted(os.listdir(tmp_path)) == ["job.yaml", "scan.x3p"]
    proc = subprocess.run([sys.executable, "-c", block + "import vecontact as vc\ntry:\n vc.read_topography('scan.x3p')\n"
                           "except vc.InputError as e: print(e.key, e.problem)"], capture_output=True, text=True,
                          cwd=tmp_path, env=ENV, timeout=120)
    assert proc.stdout.startswith("surface.file scan.x3p is an instrument file") and "[topography]" in proc.stdout


def test_exact_solve_of_an_x3p_file_from_the_command_line_serial_and_2_ranks(tmp_path):
    """`vecontact run` on an instrument file: the farm solves the prepared surface; the row equals
    vc.solve on vc.read_topography of the same file (the same computation), and 2 ranks agree to
    the solver tolerance."""
    pytest.importorskip("SurfaceTopography")
    import vecontact as vc
    from vecontact.io.results import read_cases
    h, dx = scan()
    write_x3p(tmp_path / "scan.x3p", h, dx, dx)
    job = {"surface": {"spectrum": "file", "file": "scan.x3p"}, "material": MATERIAL,
           "sweep": {"velocity": [0.01], "pressure": [1e5]}, "numerics": {"enabled": True}}
    rows = {}
    for ranks in (1, 2):
        (tmp_path / f"job{ranks}.yaml").write_text(yaml.safe_dump(dict(job, output=f"out{ranks}.h5")))
        cmd = [sys.executable, "-m", "vecontact", "run", f"job{ranks}.yaml", "--no-plot", "--quiet"]
        if ranks > 1:
            cmd = [mpiexec(), "-n", str(ranks)] + cmd
        proc = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path, env=ENV, timeout=600)
        assert proc.returncode == 0, proc.stderr
        rows[ranks] = read_cases(str(tmp_path / f"out{ranks}.h5"))[0]
    s = vc.read_topography(tmp_path / "scan.x3p")
    r = vc.solve(s, vc.modulus(**MATERIAL), 0.01, 1e5)
    one, two = rows[1], rows[2]
    assert one["status"] == 1 and two["status"] == 1 and one["N"] == 60 and r.converged
    # same equations, FFT plans chosen per process: equal to the solver tolerance (1e-8, scale-free);
    # the contact area may differ by a grid point whose pressure is at rounding level
    for other in (two, {"area": r.area, "mu": r.mu}):
        assert abs(other["area"] - one["area"]) <= 1.0 / 60 ** 2
        assert other["mu"] == pytest.approx(one["mu"], rel=1e-6)
    assert one["theory_area"] == pytest.approx(vc.theory(s, vc.modulus(**MATERIAL), 0.01, 1e5).area, rel=1e-12)
