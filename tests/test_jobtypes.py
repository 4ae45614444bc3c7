"""The typed job (vecontact.jobtypes): frozen sections, one home per derived quantity, the resolved
dict given back unchanged (stored YAML and restart hash), results files of earlier versions read."""
import copy
import dataclasses
import glob
import hashlib
import math
import os
import shutil

import numpy as np
import pytest
import yaml

from vecontact import job as jobs
from vecontact.jobtypes import AreaRange, Job, Material, Numerics, Surface, Sweep, Theory, fft_size

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DEMO = os.path.join(ROOT, "jobs", "demo.yaml")
PAPER = os.path.join(ROOT, "jobs", "paper.yaml")
DMA = {"model": "table", "file": os.path.join(ROOT, "examples", "data", "dma_master_curve.csv"),
       "frequency_unit": "Hz", "modulus_unit": "MPa", "columns": ["frequency (Hz)", "E' (MPa)", "E'' (MPa)"]}
SHIPPED = sorted(glob.glob(os.path.join(ROOT, "jobs", "*.yaml")) + glob.glob(os.path.join(ROOT, "examples", "*.yaml")))


def _raw(path=DEMO, **sections):
    raw = yaml.safe_load(open(path))
    raw.update(sections)
    return raw


def test_every_section_is_frozen_and_holds_tuples():
    job = jobs.load(DEMO)
    parts = [job, job.surface, job.material, job.sweep, job.theory, job.numerics, job.sweep.pressure]
    assert [type(p) for p in parts] == [Job, Surface, Material, Sweep, Theory, Numerics, AreaRange]
    for part in parts:
        name = dataclasses.fields(part)[0].name
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(part, name, None)
    assert isinstance(job.surface.q1, tuple) and isinstance(job.sweep.velocity, tuple)
    assert isinstance(job.numerics.fields, tuple) and isinstance(job.surface.realisations(2e6), tuple)


def test_length_and_grid_of_a_self_affine_surface():
    """L = 2 pi / q0 and N = 2 null_band q1 / q0 (docs/conventions.md §1, §2): demo.yaml has
    q0 = 2.5e5 1/m, null_band 8, q1 = 8 q0 and 16 q0."""
    s = jobs.load(DEMO).surface
    assert s.length == 2.0 * math.pi / 2.5e5
    assert [s.grid(q1) for q1 in s.q1] == [2 * 8 * 8, 2 * 8 * 16] == [128, 256]
    assert s.grids() == {repr(2.0e6): 128, repr(4.0e6): 256}
    paper = jobs.load(PAPER).surface
    assert [paper.grid(q1) for q1 in paper.q1] == [512, 1024, 2048, 4096]
    assert paper.realisations(6.4e7) == (1,) and paper.realisations(8e6) == (1, 2, 3, 4)


def test_length_and_grid_of_a_measured_spectrum_and_of_a_height_file(tmp_path):
    """psd: L = 2 pi / q0 with q0 = 2 pi / length, N = the FFT size at or above 2 null_band q1 / q0;
    a height file: its own period and N."""
    psd = jobs.load(os.path.join(ROOT, "examples", "psd_job.yaml")).surface
    assert psd.spectrum == "psd" and psd.q0 == 2.0 * math.pi / psd.period
    assert psd.length == 2.0 * math.pi / psd.q0
    q1 = psd.q1[0]
    assert psd.grid(q1) == fft_size(2 * psd.null_band * q1 / psd.q0 * (1 - 1e-12))
    np.save(tmp_path / "h.npy", np.zeros((24, 24)))
    job = jobs.resolve(_raw(surface={"spectrum": "file", "file": "h.npy", "length": 3e-5}), str(tmp_path))
    assert (job.surface.length, job.surface.grid(), job.surface.q1) == (3e-5, 24, ())


def test_modulus_is_built_once_and_a_table_read_once(monkeypatch):
    """Validation reads the table; the theory sweep and the solver setup reuse that modulus."""
    from mpi4py import MPI
    from vecontact import cases
    from vecontact.farm.case import Setup
    from vecontact.physics import modulus as moduli
    from vecontact.runner import spectra
    reads = []

    def counting(*args, **kw):
        reads.append(args[0])
        return read(*args, **kw)
    read = moduli.read_columns
    monkeypatch.setattr(moduli, "read_columns", counting)
    job = jobs.resolve(_raw(material=dict(DMA), sweep={"velocity": [0.01], "pressure": [1e5, 2e5]}), ROOT)
    assert reads == [DMA["file"]]
    E = job.material.modulus()
    assert isinstance(E, moduli.Table) and job.material.modulus() is E
    psds = spectra(job, MPI.COMM_SELF, warn=False)
    cases.theory(job, psds, cases.expand(job, psds))
    assert Setup.from_job(job, {}).modulus is E
    assert reads == [DMA["file"]]
    # a changed material is a new value with its own modulus (the cache is not carried over)
    shifted = dataclasses.replace(job.material, vertical_shift=2.0)
    assert shifted.modulus().E0 == pytest.approx(2.0 * E.E0, rel=1e-12) and len(reads) == 2
    assert shifted != job.material and dataclasses.replace(job.material) == job.material


@pytest.mark.parametrize("path", SHIPPED, ids=[os.path.basename(p) for p in SHIPPED])
def test_round_trip_load_to_dict_from_dict(path):
    job = jobs.load(path)
    d = job.to_dict()
    assert Job.from_dict(d) == job
    assert Job.from_dict(copy.deepcopy(d)).to_dict() == d
    text = jobs.to_yaml(job)
    assert jobs.to_yaml(Job.from_dict(yaml.safe_load(text))) == text       # shared seed lists included
    assert list(d) == ["output", "surface", "material", "sweep", "theory", "numerics"]


def test_stored_job_and_restart_hash_unchanged():
    """A contract, bit for bit: the stored job_yaml and the physics hash of the shipped jobs are
    those of the dict-based job (before vecontact.jobtypes, commit e130847). A different hash would
    refuse to resume every results file written before; a different text changes their provenance."""
    expected = {
        "demo": ("7e41b33dd3e1b2196ead727bc0ebe84be435b2590f149c7e343e52971626d3d5",
                 "57fded5fdf3008f3a1569ece88f0a6c8a37e1c5ef5c74f5086b1172e01799261"),
        "paper": ("b284dbf8663d7ce287f67fedd895b6a439e17c7035155bc191bd5940acb5e48b",
                  "955196d80f74961e7dd3ee0ee5373296004fa0960de3559adc7aa6eaf5c0313e"),
    }
    for name, (physics, text) in expected.items():
        job = jobs.load(os.path.join(ROOT, "jobs", f"{name}.yaml"), output=f"/results/{name}.h5")
        assert jobs.physics_hash(job) == physics, name
        assert hashlib.sha256(jobs.to_yaml(job).encode()).hexdigest() == text, name


def test_results_file_of_an_earlier_version_is_read_and_resumed(tmp_path):
    """results/paper.h5 (written by the dict-based job): its stored job reads back to the same text
    and hash, the analysis and status read it, and jobs/paper.yaml may resume it."""
    import h5py
    from vecontact.analysis.study import load_study
    from vecontact.io.results import ResultsFile
    from vecontact.status import read_status
    src = os.path.join(ROOT, "results", "paper.h5")
    if not os.path.exists(src):
        pytest.skip("results/paper.h5 is not in this checkout")
    path = str(tmp_path / "paper.h5")
    shutil.copy(src, path)
    with h5py.File(path, "r") as f:
        text, stored_hash, rows = f.attrs["job_yaml"], f.attrs["physics_hash"], len(f["cases"])
    stored = Job.from_dict(yaml.safe_load(text))
    assert jobs.to_yaml(stored) == text and jobs.physics_hash(stored) == stored_hash
    job = jobs.load(PAPER, output=path)
    assert jobs.physics_hash(job) == stored_hash
    assert dataclasses.replace(stored, output=path) == job
    writer = ResultsFile.open(path, jobs.to_yaml(job), jobs.physics_hash(job), 1)     # raises if refused
    assert len(writer.done()) == rows > 0
    study = load_study(path)
    assert study.job == stored and study.seeds(8e6) == [1, 2, 3, 4] and study.q1_label(8e6) == "32 q0"
    assert read_status(path)["numerics"] is True


def test_partial_stored_job_takes_the_defaults():
    """A stored job lacking keys (an older version's) reads with the defaults of the job file."""
    job = Job.from_dict({"output": "o.h5", "surface": {"spectrum": "self-affine", "q0": 1e5, "q1": [1e6],
                                                        "null_band": 2, "seeds": [1]},
                         "material": {"model": "table", "file": "dma.csv"}})
    assert job.surface.amplitudes == "fixed" and job.surface.grid(1e6) == 40
    assert (job.material.frequency_unit, job.material.modulus_unit, job.material.vertical_shift) == ("rad/s", "Pa", 1.0)
    assert job.numerics == Numerics() and job.theory == Theory() and job.sweep == Sweep()
