"""Job files: load a YAML job, validate it completely, and resolve defaults.

Every problem raises :class:`vecontact.errors.InputError` naming the dotted key
(``surface.q1``, ``sweep.pressure.num``...) before any work starts. The resolved job is a
:class:`vecontact.jobtypes.Job` (frozen sections, every default filled in, every sweep axis
expanded); ``job.to_dict()`` is the plain dict stored as YAML provenance (:func:`to_yaml`) and
hashed for restarts (:func:`physics_hash`).

Units are SI throughout: wavevectors in 1/m, lengths in m, moduli and pressures in Pa,
times in s, velocities in m/s.
"""
import hashlib
import json
import math
import os

import numpy as np
import yaml

from vecontact.errors import InputError
from vecontact.jobtypes import Job, Material, Numerics, Surface, Sweep, Theory, grid_points, nyquist_points
from vecontact.solver.options import parse as parse_petsc

MODELS = ("elastic", "sls", "prony", "havriliak-negami", "table")
SPECTRA = ("self-affine", "file", "psd")
FIELDS = ("pressure", "gap", "displacement", "contact")
SOLVERS = ("snes", "pk")
FFT_PLANNERS = ("measure", "patient")     # FFTW planners a job may ask for (benchmarks/RESULTS.md)

# Keys that do not change any number in the results: ignored by the restart hash. A seed's cases
# do not depend on the other seeds, so a sweep may be resumed with more (or fewer) seeds.
NON_PHYSICS = {("output",), ("numerics", "ranks_per_case"), ("numerics", "threads"),
               ("numerics", "fft_planner"), ("numerics", "fields"), ("numerics", "downsample"),
               ("surface", "seeds")}


# --------------------------------------------------------------------------------------------
# small typed readers
def _number(d, key, path, *, default=None, required=True, lo=None, hi=None, lo_open=False,
            hi_open=False, integer=False):
    """Read a finite number d[key]; range [lo, hi] (open ends with lo_open/hi_open)."""
    name = f"{path}.{key}" if path else key
    if key not in d:
        if default is not None or not required:
            return default
        raise InputError(name, "is required")
    v = d[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        if isinstance(v, str):
            try:
                v = float(v)  # YAML reads '1e4' (no dot) as a string
            except ValueError:
                raise InputError(name, f"must be a number, got {d[key]!r}") from None
        else:
            raise InputError(name, f"must be a number, got {type(v).__name__} {v!r}")
    if not math.isfinite(v):
        raise InputError(name, f"must be finite, got {v!r}")
    if integer:
        if float(v) != int(v):
            raise InputError(name, f"must be an integer, got {v!r}")
        v = int(v)
    if lo is not None and (v < lo or (lo_open and v == lo)):
        raise InputError(name, f"must be {'>' if lo_open else '>='} {lo:g}, got {v:g}")
    if hi is not None and (v > hi or (hi_open and v == hi)):
        raise InputError(name, f"must be {'<' if hi_open else '<='} {hi:g}, got {v:g}")
    return v


def _choice(d, key, path, choices, default=None):
    name = f"{path}.{key}" if path else key
    v = d.get(key, default)
    if v is None:
        raise InputError(name, f"is required (one of {', '.join(choices)})")
    if not isinstance(v, str) or v not in choices:
        raise InputError(name, f"must be one of {', '.join(choices)}, got {v!r}")
    return v


def _bool(d, key, path, default):
    v = d.get(key, default)
    if not isinstance(v, bool):
        raise InputError(f"{path}.{key}", f"must be true or false, got {v!r}")
    return v


def _section(job, key, required=True):
    if key not in job:
        if required:
            raise InputError(key, "section is required")
        return {}
    v = job[key]
    if v is None:
        return {}
    if not isinstance(v, dict):
        raise InputError(key, f"must be a mapping of keys, got {type(v).__name__}")
    return v


def _unknown(d, path, allowed):
    for k in d:
        if k not in allowed:
            name = f"{path}.{k}" if path else str(k)
            raise InputError(name, f"unknown key (allowed: {', '.join(sorted(allowed))})")


def _number_list(d, key, path, *, lo=None, lo_open=False, integer=False, default=None):
    """A value or a non-empty list of values, each validated like :func:`_number`."""
    name = f"{path}.{key}"
    v = d.get(key, default)
    if v is None:
        raise InputError(name, "is required")
    items = v if isinstance(v, list) else [v]
    if not items:
        raise InputError(name, "must not be empty")
    out = []
    for item in items:
        out.append(_number({key: item}, key, path, lo=lo, lo_open=lo_open, integer=integer))
    if len(set(out)) != len(out):
        raise InputError(name, "contains duplicate values")
    return out


def _columns(d, path, names):
    """``columns`` of a table file: None (the file has exactly these columns) or a list naming one
    column per entry of ``names`` by 0-based index or header name (checked against the file later)."""
    v = d.get("columns")
    if v is not None and (not isinstance(v, list) or len(v) != len(names)
                          or not all(isinstance(c, (int, str)) and not isinstance(c, bool) for c in v)):
        raise InputError(f"{path}.columns", f"must list {len(names)} columns ({', '.join(names)}): 0-based "
                                            f"indices or header names, got {v!r}")
    return v


def _path(d, key, path, base, must_exist=True):
    name = f"{path}.{key}"
    v = d.get(key)
    if not isinstance(v, str) or not v:
        raise InputError(name, "must be a file path")
    full = v if os.path.isabs(v) else os.path.normpath(os.path.join(base, v))
    if must_exist and not os.path.isfile(full):
        raise InputError(name, f"file not found: {full}")
    return full


# --------------------------------------------------------------------------------------------
# sections
def _surface(job, base):
    s = _section(job, "surface")
    p = "surface"
    spectrum = _choice(s, "spectrum", p, SPECTRA, default="self-affine")
    common = {"spectrum", "null_band", "seeds", "amplitudes"}
    out = {"spectrum": spectrum}
    out["amplitudes"] = _choice(s, "amplitudes", p, ("fixed", "gaussian"), default="fixed")
    if spectrum == "file":
        return _surface_file(s, p, base, common, out)
    if spectrum == "psd":
        return _surface_psd(job, s, p, base, common, out)
    _unknown(s, p, common | {"q0", "qr", "q1", "hurst", "C0", "hrms"})
    q0 = out["q0"] = _number(s, "q0", p, lo=0, lo_open=True)
    qr = out["qr"] = _number(s, "qr", p, default=q0, lo=0, lo_open=True)
    q1 = out["q1"] = sorted(_number_list(s, "q1", p, lo=0, lo_open=True))
    out["hurst"] = _number(s, "hurst", p, lo=0, hi=1, lo_open=True, hi_open=True)
    if qr < q0:
        raise InputError(f"{p}.qr", f"must be >= q0 = {q0:g}, got {qr:g}")
    for v in q1:
        if v <= qr:
            raise InputError(f"{p}.q1", f"every q1 must exceed qr = {qr:g}, got {v:g}")
    if ("C0" in s) == ("hrms" in s):
        raise InputError(f"{p}.C0", "give exactly one of C0 (m^4) or hrms (m)")
    if "C0" in s:
        out["C0"] = _number(s, "C0", p, lo=0, lo_open=True)
    else:
        out["hrms"] = _number(s, "hrms", p, lo=0, lo_open=True)
    out["null_band"] = nb = _number(s, "null_band", p, default=8, lo=1)
    out["seeds"] = _seeds(s, p, q1)
    for v in q1:
        n_float = nyquist_points(q0, v, nb)
        n = grid_points(spectrum, q0, v, nb)
        if abs(n - n_float) > 1e-6 * n_float:
            raise InputError(f"{p}.q1", f"grid size N = 2 null_band q1 / q0 = {n_float:.6g} "
                                        f"is not an integer for q1 = {v:g}")
        if n < 4:
            raise InputError(f"{p}.q1", f"grid size N = {n} is too small (need N >= 4)")
    return Surface.from_dict(out)


def _surface_file(s, p, base, common, out):
    """``spectrum: file``: heights from a .npy / .h5 file (raw, periodic, ``length`` given) or an
    instrument scan (SurfaceTopography; its size from the file, see vecontact.io.topography)."""
    from vecontact.io.topography import is_instrument_file, read_topography
    _unknown(s, p, common | {"file", "length", "dataset"})
    out["file"] = _path(s, "file", p, base)
    out["dataset"] = s.get("dataset")
    if out["dataset"] is not None and not isinstance(out["dataset"], str):
        raise InputError(f"{p}.dataset", "must be an HDF5 dataset name or the channel of an instrument file")
    if is_instrument_file(out["file"]):
        if "length" in s:
            raise InputError(f"{p}.length", "an instrument file states its own size; length is for "
                                            ".npy and .h5 height files")
        _, out["length"], out["source"] = read_topography(out["file"], out["dataset"], key=f"{p}.file")
    else:
        out["length"] = _number(s, "length", p, lo=0, lo_open=True)
    out["seeds"] = [0]
    out["null_band"] = None
    return Surface.from_dict(out)


#: Largest grid (points per side) a job on a measured spectrum may ask the solver for.
MAX_PSD_GRID = 16384


def _surface_psd(job, s, p, base, common, out):
    """``spectrum: psd``: a measured C(q) table (vecontact.io.psd). The system is a square of side
    ``length`` (default 2 pi / q_min of the table), q0 = 2 pi / length; ``q1`` (default the table's
    q_max) cuts the spectrum; the grid resolves null_band q1: N = fft_size(2 null_band q1 / q0)."""
    from vecontact.io.psd import read_psd
    _unknown(s, p, common | {"file", "dimension", "columns", "length", "q1"})
    out["file"] = _path(s, "file", p, base)
    out["dimension"] = _number(s, "dimension", p, default=2, integer=True, lo=1, hi=2)
    out["columns"] = cols = _columns(s, p, ("q", "C"))
    psd = read_psd(out["file"], out["dimension"], key=f"{p}.file", columns=cols)
    out["sha256"] = _file_hash(out["file"])
    length = _number(s, "length", p, required=False, lo=0, lo_open=True)
    out["length"] = L = float(length) if length is not None else 2.0 * math.pi / psd.q_min
    q0 = out["q0"] = 2.0 * math.pi / L
    q1 = out["q1"] = sorted(_number_list(s, "q1", p, lo=0, lo_open=True, default=[psd.q_max]))
    lo = max(q0, psd.q_min)
    for v in q1:
        if not lo < v <= psd.q_max * (1 + 1e-12):
            raise InputError(f"{p}.q1", f"must lie in ({lo:.6g}, {psd.q_max:.6g}] 1/m (the table's q range "
                                        f"above 2 pi / length), got {v:g}")
    out["null_band"] = nb = _number(s, "null_band", p, default=8, lo=1)
    out["seeds"] = _seeds(s, p, q1)
    out["table"] = {"rows": int(psd.q.size), "q_min": psd.q_min, "q_max": psd.q_max, "hrms": psd.hrms()}
    numerics = job.get("numerics") if isinstance(job.get("numerics"), dict) else {}
    for v in q1:
        n = grid_points(out["spectrum"], q0, v, nb)
        if numerics.get("enabled") is True and n > MAX_PSD_GRID:
            raise InputError(f"{p}.q1", f"the solver would need a {n} x {n} grid for q1 = {v:g} 1/m with "
                                        f"length {L:.4g} m (N > {MAX_PSD_GRID}): give a smaller q1 or length")
    return Surface.from_dict(out)


def _seeds(s, p, q1):
    """``seeds``: a list (every q1), or a mapping {q1: list, ..., other: list} so that the small
    systems get more realisations than the large ones. Resolved to the list, or to
    {repr(q1): list} for every q1 (read it with :meth:`Surface.realisations`)."""
    v = s.get("seeds", [1])
    if not isinstance(v, dict):
        return _number_list(s, "seeds", p, lo=0, integer=True, default=[1])
    name = f"{p}.seeds"
    other = _number_list(v, "other", name, lo=0, integer=True) if "other" in v else None
    given = {}
    for k in v:
        if k == "other":
            continue
        key = _number({"q1": k}, "q1", name)
        match = [x for x in q1 if abs(x - key) <= 1e-9 * x]
        if not match:
            raise InputError(f"{name}.{k}", f"is not one of surface.q1 ({', '.join(f'{x:g}' for x in q1)})")
        given[repr(float(match[0]))] = _number_list(v, k, name, lo=0, integer=True)
    out = {}
    for x in q1:
        seeds = given.get(repr(float(x)), other)
        if seeds is None:
            raise InputError(name, f"gives no seeds for q1 = {x:g} (add it, or an 'other' entry)")
        out[repr(float(x))] = seeds
    return out


def _material(job, base):
    """The ``material`` section as a :class:`Material`; a table file is read now (a bad file is an
    input error, found before any work) and the modulus kept (:meth:`Material.modulus`)."""
    m = _section(job, "material")
    p = "material"
    model = _choice(m, "model", p, MODELS)
    out = {"model": model}
    out["nu"] = _number(m, "nu", p, default=0.5, lo=-1, hi=0.5, lo_open=True)
    keys = {"model", "nu"}
    if model == "elastic":
        keys |= {"E0"}
        out["E0"] = _number(m, "E0", p, lo=0, lo_open=True)
    elif model in ("sls", "havriliak-negami"):
        keys |= {"E0", "Einf", "tau"}
        out["E0"] = _number(m, "E0", p, lo=0, lo_open=True)
        out["Einf"] = _number(m, "Einf", p, lo=0, lo_open=True)
        out["tau"] = _number(m, "tau", p, lo=0, lo_open=True)
        if out["Einf"] <= out["E0"]:
            raise InputError(f"{p}.Einf", f"must exceed E0 = {out['E0']:g} (glassy > rubbery), "
                                          f"got {out['Einf']:g}")
        if model == "havriliak-negami":
            keys |= {"alpha", "beta"}
            out["alpha"] = _number(m, "alpha", p, lo=0, hi=1, lo_open=True)
            out["beta"] = _number(m, "beta", p, lo=0, hi=1, lo_open=True)
    elif model == "prony":
        keys |= {"E0", "terms"}
        out["E0"] = _number(m, "E0", p, lo=0, lo_open=True)
        terms = m.get("terms")
        if not isinstance(terms, list) or not terms:
            raise InputError(f"{p}.terms", "must be a non-empty list of [dE, tau] pairs")
        out["terms"] = []
        for i, t in enumerate(terms):
            if not isinstance(t, list) or len(t) != 2:
                raise InputError(f"{p}.terms[{i}]", f"must be a pair [dE, tau], got {t!r}")
            de = _number({"dE": t[0]}, "dE", f"{p}.terms[{i}]", lo=0, lo_open=True)
            tau = _number({"tau": t[1]}, "tau", f"{p}.terms[{i}]", lo=0, lo_open=True)
            out["terms"].append([de, tau])
    else:  # table
        keys |= {"file", "wlf", "frequency_unit", "modulus_unit", "columns", "vertical_shift"}
        out["file"] = _path(m, "file", p, base)
        from vecontact.physics.modulus import FREQUENCY_UNITS, MODULUS_UNITS
        out["frequency_unit"] = _choice(m, "frequency_unit", p, tuple(FREQUENCY_UNITS), default="rad/s")
        out["modulus_unit"] = _choice(m, "modulus_unit", p, tuple(MODULUS_UNITS), default="Pa")
        out["columns"] = _columns(m, p, ("frequency", "E'", "E''"))
        out["vertical_shift"] = _number(m, "vertical_shift", p, default=1.0, lo=0, lo_open=True)
        wlf = m.get("wlf")
        if wlf is not None:
            if not isinstance(wlf, dict):
                raise InputError(f"{p}.wlf", "must be a mapping with C1, C2, T_ref, T")
            _unknown(wlf, f"{p}.wlf", {"C1", "C2", "T_ref", "T"})
            w = {k: _number(wlf, k, f"{p}.wlf") for k in ("C1", "C2", "T_ref", "T")}
            if w["C2"] + w["T"] - w["T_ref"] <= 0:
                raise InputError(f"{p}.wlf.T", "C2 + T - T_ref must be > 0 (WLF diverges)")
            out["wlf"] = w
        else:
            out["wlf"] = None
    _unknown(m, p, keys)
    material = Material.from_dict(out)
    if model == "table":
        material.modulus()
    return material


def _sweep(job):
    s = _section(job, "sweep")
    p = "sweep"
    _unknown(s, p, {"velocity", "pressure"})
    velocity = sorted(_number_list(s, "velocity", p, lo=0))
    pr = s.get("pressure")
    if isinstance(pr, dict) and ("area_min" in pr or "area_max" in pr):
        # pressures chosen per (q1, v) from the theory so that A/A0 spans [area_min, area_max]
        _unknown(pr, f"{p}.pressure", {"area_min", "area_max", "num"})
        lo = _number(pr, "area_min", f"{p}.pressure", lo=0, hi=1, lo_open=True, hi_open=True)
        hi = _number(pr, "area_max", f"{p}.pressure", lo=0, hi=1, lo_open=True, hi_open=True)
        num = _number(pr, "num", f"{p}.pressure", lo=1, integer=True)
        if hi < lo:
            raise InputError(f"{p}.pressure.area_max", f"must be >= area_min = {lo:g}, got {hi:g}")
        return Sweep.from_dict({"velocity": [float(v) for v in velocity],
                                "pressure": {"area_min": lo, "area_max": hi, "num": num}})
    if isinstance(pr, dict):
        _unknown(pr, f"{p}.pressure", {"min", "max", "num"})
        lo = _number(pr, "min", f"{p}.pressure", lo=0, lo_open=True)
        hi = _number(pr, "max", f"{p}.pressure", lo=0, lo_open=True)
        num = _number(pr, "num", f"{p}.pressure", lo=1, integer=True)
        if hi < lo:
            raise InputError(f"{p}.pressure.max", f"must be >= min = {lo:g}, got {hi:g}")
        if num > 1 and hi == lo:
            raise InputError(f"{p}.pressure.max", "equals min but num > 1")
        pressure = [float(x) for x in np.geomspace(lo, hi, num)]
    else:
        pressure = sorted(_number_list(s, "pressure", p, lo=0, lo_open=True))
    return Sweep.from_dict({"velocity": [float(v) for v in velocity], "pressure": pressure})


def _theory(job):
    t = _section(job, "theory", required=False)
    _unknown(t, "theory", {"gamma", "nq", "nphi"})
    out = {"gamma": _number(t, "gamma", "theory", default=0.5, lo=0, hi=1)}
    out["nq"] = _number(t, "nq", "theory", required=False, lo=16, integer=True)
    out["nphi"] = _number(t, "nphi", "theory", required=False, lo=8, integer=True)
    return Theory.from_dict(out)


def _numerics(job, material):
    n = _section(job, "numerics", required=False)
    p = "numerics"
    _unknown(n, p, {"enabled", "solver", "tolerance", "petsc", "fields", "downsample",
                    "ranks_per_case", "coarse", "max_iterations", "threads", "fft_planner"})
    out = {"enabled": _bool(n, "enabled", p, False)}
    out["solver"] = _choice(n, "solver", p, SOLVERS, default="snes")
    if out["solver"] == "pk" and material.model != "elastic":
        raise InputError(f"{p}.solver", "pk (Polonsky-Keer) is valid only for elastic materials: "
                                        "the viscoelastic operator is not symmetric")
    out["tolerance"] = _number(n, "tolerance", p, default=1e-8, lo=0, hi=1e-2, lo_open=True)
    out["petsc"] = parse_petsc(n.get("petsc"), f"{p}.petsc")
    fields = n.get("fields", [])
    if isinstance(fields, str):
        fields = [fields]
    if not isinstance(fields, list):
        raise InputError(f"{p}.fields", f"must be a list from {', '.join(FIELDS)}")
    for f in fields:
        if f not in FIELDS:
            raise InputError(f"{p}.fields", f"unknown field {f!r} (allowed: {', '.join(FIELDS)})")
    out["fields"] = list(dict.fromkeys(fields))
    out["downsample"] = _number(n, "downsample", p, default=1, lo=1, integer=True)
    rpc = n.get("ranks_per_case", "auto")
    out["ranks_per_case"] = rpc if rpc == "auto" else _number(n, "ranks_per_case", p, lo=1, integer=True)
    out["coarse"] = _bool(n, "coarse", p, True)
    out["max_iterations"] = _number(n, "max_iterations", p, required=False, lo=1, integer=True)
    out["threads"] = _number(n, "threads", p, default=1, lo=1, integer=True)
    if "fft_planner" in n:      # stored only when given: earlier jobs keep their text
        out["fft_planner"] = _choice(n, "fft_planner", p, FFT_PLANNERS)
    return Numerics.from_dict(out)


# --------------------------------------------------------------------------------------------
def resolve(raw, base="."):
    """Validate a parsed job (dict) and return the resolved :class:`Job`; ``base`` resolves relative
    paths."""
    if not isinstance(raw, dict):
        raise InputError("", "a job file must be a YAML mapping of sections")
    _unknown(raw, "", {"output", "surface", "material", "sweep", "theory", "numerics"})
    out = raw.get("output")
    if not isinstance(out, str) or not out.strip():
        raise InputError("output", "must be the path of the HDF5 file to write")
    if not out.endswith((".h5", ".hdf5")):
        raise InputError("output", f"must end in .h5 or .hdf5, got {out!r}")
    output = out if os.path.isabs(out) else os.path.normpath(os.path.join(base, out))
    surface = _surface(raw, base)
    material = _material(raw, base)
    sweep = _sweep(raw)
    theory = _theory(raw)
    numerics = _numerics(raw, material)
    if surface.spectrum == "file" and surface.amplitudes != "fixed":
        raise InputError("surface.amplitudes", "applies to generated surfaces only")
    return Job(output=output, surface=surface, material=material, sweep=sweep, theory=theory, numerics=numerics)


def load(path, output=None):
    """Read and validate a job file. Relative paths inside it are relative to the job's folder."""
    if not os.path.isfile(path):
        raise InputError("job", f"file not found: {path}")
    try:
        with open(path) as f:
            raw = yaml.safe_load(f)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}" if mark is not None else ""
        raise InputError("job", f"{path} is not valid YAML{where}") from None
    if raw is None:
        raise InputError("job", f"{path} is empty")
    if output is not None and isinstance(raw, dict):
        raw = dict(raw, output=output)
    base = os.path.dirname(os.path.abspath(path))
    # Outputs are relative to the working directory, like every command-line tool.
    if isinstance(raw, dict) and isinstance(raw.get("output"), str):
        raw = dict(raw, output=os.path.abspath(raw["output"]))
    return resolve(raw, base)


def physics_hash(job):
    """SHA-256 of everything in the :class:`Job` that changes results (restart guard): of the JSON
    text of its resolved dict, without the NON_PHYSICS keys, with the hashes of its input files."""
    j = job.to_dict()
    for key in NON_PHYSICS:
        d = j
        for k in key[:-1]:
            d = d.get(k, {})
        d.pop(key[-1], None)
    if j["surface"].get("spectrum") == "file":
        j["surface"]["file_sha256"] = _file_hash(j["surface"]["file"])
    if j["material"].get("model") == "table":
        j["material"]["file_sha256"] = _file_hash(j["material"]["file"])
    text = json.dumps(j, sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()


def _file_hash(path):
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def to_yaml(job):
    """The resolved :class:`Job` as YAML text (the ``job_yaml`` of results and surface files)."""
    return yaml.safe_dump(job.to_dict(), sort_keys=False, default_flow_style=None)
