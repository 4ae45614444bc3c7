"""The results file: one HDF5 file per job, written by one rank, never half-written.

Layout (see docs/results-format.md):

- root attributes: ``format``, ``vecontact_version``, ``git_commit``, ``job_yaml``,
  ``physics_hash``, ``created``, ``updated``, ``nranks``, ``complete`` (version, commit and ranks of
  the latest run);
- ``/cases``: compound dataset, one row per finished (q1, seed, velocity, pressure) case,
  sorted by those four columns; attribute ``units`` (JSON {column: unit}) and ``status_codes``;
  column ``run`` indexes ``/runs``; the columns are those of :mod:`vecontact.rows`;
- ``/runs``: one JSON object per invocation that wrote the file (a restarted sweep has several):
  code version and git commit of the running code, start time, ranks, host, command line, PETSc
  options, library versions;
- ``/diagnostics``: one JSON string per row of ``/cases`` (same order; "" for theory-only rows): the
  solver's reason, Newton residual history, active-set changes, Krylov counts and FFT pairs per level;
- ``/theory``: Persson's theory (``q``, ``P_q``, dense ``curves``) per q1;
- ``/spectrum``: C(q) per q1 (Fig. 1);
- ``/fields/<case>``: optional per-case fields, as external links to files in
  ``<output>.fields/`` (each written atomically), so the main file stays small.

Crash safety: every commit writes the whole (small) main file to ``<output>.tmp-<pid>``,
fsyncs it and renames it over the old one (atomic on POSIX), then fsyncs the folder. A kill
at any moment leaves either the previous or the new complete file (and perhaps the temporary, which
the next writer removes).
"""
import contextlib
import glob
import json
import os
import platform
import subprocess
import sys
import time

import h5py
import numpy as np

from vecontact import __version__
from vecontact.errors import InputError, ResultsFileError
from vecontact.rows import CASE_DTYPE, COLUMNS, STATUS_CODES, case_key, empty_row

FORMAT = "vecontact-results/1"
TMP_INFIX = ".tmp-"      # a commit writes <output>.tmp-<pid>, then renames it over <output>


def git_commit(where=None):
    """HEAD of the checkout the package runs from, with "+dirty" if tracked files under the package
    directory (or under ``where``) differ from it.  Only the code counts: a sweep that writes a tracked
    results file (``results/paper.h5``, committed as it grows) or a report that rewrites tracked
    figures leaves its code clean.  Read once per run (ResultsFile.open): HEAD may move while a long
    sweep runs."""
    here = where or os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

    def git(*args):
        return subprocess.run(["git", *args], cwd=here, capture_output=True, text=True, timeout=10)
    try:
        out = git("rev-parse", "HEAD")
        if out.returncode != 0:
            return "unknown (not a git checkout)"
        status = git("status", "--porcelain", "--untracked-files=no", "--", ".")
        dirty = status.returncode != 0 or bool(status.stdout.strip())
        return out.stdout.strip() + ("+dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown (git not available)"


def run_record(nranks, **extra):
    """Provenance of this invocation (one entry of ``/runs``)."""
    versions = {"python": platform.python_version(), "numpy": np.__version__, "h5py": h5py.__version__}
    for mod in ("mpi4py", "petsc4py", "pyfftw"):
        m = sys.modules.get(mod)
        if m is not None:
            versions[mod] = getattr(m, "__version__", "?")
    rec = {"started": time.strftime("%Y-%m-%dT%H:%M:%S%z"), "vecontact_version": __version__,
           "git_commit": git_commit(), "nranks": int(nranks), "host": platform.node(),
           "argv": list(sys.argv), "versions": versions}
    rec.update(extra)
    return rec


def _as_case_dtype(table):
    """Rows of a file written with fewer columns (an older version), copied by name."""
    out = np.empty(table.shape, dtype=CASE_DTYPE)
    out[...] = empty_row()
    for name in table.dtype.names:
        if name in CASE_DTYPE.names:
            out[name] = table[name]
    return out


def _fsync_dir(path):
    try:
        fd = os.open(os.path.dirname(os.path.abspath(path)) or ".", os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def atomic_h5(path, fill):
    """Write an HDF5 file atomically: ``fill(h5file)`` into a temporary, fsync, rename."""
    tmp = f"{path}{TMP_INFIX}{os.getpid()}"
    try:
        with h5py.File(tmp, "w") as f:
            fill(f)
            f.flush()
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
        _fsync_dir(path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def _process_alive(pid):
    """True while a process with this pid runs on this host.  A zombie (dead, not yet reaped by its
    parent, e.g. a rank that mpiexec killed a moment ago) is not alive: it can write nothing more."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:             # someone else's process: alive
        return True
    try:
        with open(f"/proc/{pid}/stat") as fh:
            state = fh.read().rsplit(")", 1)[1].split()[0]   # the name in (...) may contain spaces
    except (OSError, IndexError):                            # no /proc (macOS): trust kill
        return True
    return state not in ("Z", "X")


def remove_stale_temporaries(path):
    """Remove ``<path>.tmp-<pid>`` files left by a writer killed mid-write (kill -9, a batch
    system's SIGKILL) whose process is gone from this host; the file itself never depends on them."""
    for tmp in glob.glob(glob.escape(path) + TMP_INFIX + "*"):
        pid = tmp.rsplit(TMP_INFIX, 1)[1]
        if not pid.isdigit() or int(pid) == os.getpid() or _process_alive(int(pid)):
            continue
        with contextlib.suppress(OSError):
            os.remove(tmp)


def write_fields_file(path, case_name, arrays, attrs):
    """Write one case's fields next to the results file ``path``, atomically, from any rank.

    The file is ``<path>.fields/<case_name>.h5``; returns its path relative to the folder of
    ``path`` (what :meth:`ResultsFile.link_fields` stores as the external link).
    """
    fields_dir = path + ".fields"
    os.makedirs(fields_dir, exist_ok=True)
    fname = os.path.join(fields_dir, f"{case_name}.h5")

    def fill(f):
        for k, v in arrays.items():
            f.create_dataset(k, data=v, compression="gzip", compression_opts=1, shuffle=True)
        for k, v in attrs.items():
            f.attrs[k] = v
    atomic_h5(fname, fill)
    return os.path.join(os.path.basename(fields_dir), f"{case_name}.h5")


class ResultsFile:
    """Rank-0 writer of a job's results; holds the finished rows in memory.

    ``ResultsFile.open(path, job_yaml, physics_hash, nranks)`` creates a new file or reopens
    an existing one for a restart (refusing foreign, corrupted or changed-job files).
    """

    def __init__(self, path, job_yaml, physics_hash, nranks):
        self.path = path
        self.job_yaml = job_yaml
        self.physics_hash = physics_hash
        self.nranks = nranks
        self.created = time.strftime("%Y-%m-%dT%H:%M:%S%z")
        self.rows = {}          # case key -> row (numpy void)
        self.groups = {}        # name -> {dataset name: array}, e.g. theory/spectrum
        self.group_attrs = {}
        self.field_links = {}   # case name -> relative file path
        self.diagnostics = {}   # case key -> JSON string
        self.runs = []          # one dict per run (JSON in the file); this run's is appended by open()
        self.run = None         # this run's index into self.runs
        self.complete = False

    # ---------------------------------------------------------------------------------------
    @classmethod
    def open(cls, path, job_yaml, physics_hash, nranks):
        self = cls(path, job_yaml, physics_hash, nranks)
        if os.path.exists(path):
            self._load_existing()
        self.run = len(self.runs)
        self.runs.append(dict(run=self.run, **run_record(nranks)))
        if not os.path.exists(path):
            folder = os.path.dirname(os.path.abspath(path))
            try:
                os.makedirs(folder, exist_ok=True)
            except OSError as exc:
                raise ResultsFileError("output", f"cannot create the folder {folder} ({exc.strerror})") from None
        remove_stale_temporaries(path)
        return self

    def _load_existing(self):
        path = self.path
        try:
            with h5py.File(path, "r") as f:
                fmt = f.attrs.get("format")
                if fmt != FORMAT:
                    raise ResultsFileError("output", f"{path} exists and is not a vecontact results "
                                                     "file; refusing to overwrite it")
                old_hash = f.attrs.get("physics_hash")
                if old_hash != self.physics_hash:
                    raise ResultsFileError("output", f"{path} was written by a job with different physics "
                                                     "(changed job file?); use another output or remove it")
                self.created = str(f.attrs.get("created", self.created))
                if "cases" in f:
                    table = _as_case_dtype(f["cases"][()])
                    diags = read_strings(f, "diagnostics", len(table))
                    for row, diag in zip(table, diags):
                        self.rows[case_key(row)] = row
                        if diag:
                            self.diagnostics[case_key(row)] = diag
                self.runs = [json.loads(r) for r in read_strings(f, "runs")]
                if "fields" in f:
                    for name in f["fields"]:
                        link = f["fields"].get(name, getlink=True)
                        if isinstance(link, h5py.ExternalLink):
                            self.field_links[name] = link.filename
        except ResultsFileError:
            raise
        except Exception as exc:  # h5py raises OSError/KeyError/... for damaged files
            raise ResultsFileError("output", f"{path} exists but cannot be read as HDF5 "
                                             f"({type(exc).__name__}); refusing to overwrite it") from None

    # ---------------------------------------------------------------------------------------
    def done(self):
        """Keys of the finished cases."""
        return set(self.rows)

    def set_group(self, name, datasets, attrs=None):
        self.groups[name] = datasets
        self.group_attrs[name] = attrs or {}

    def note_run(self, **info):
        """Add items (e.g. the PETSc options) to this run's ``/runs`` entry."""
        self.runs[self.run].update(info)

    def add_row(self, row, diagnostics=None):
        """Record a finished row (written by this run); ``diagnostics``: a JSON-serialisable dict."""
        row = np.array(row, dtype=CASE_DTYPE)[()]
        row["run"] = -1 if self.run is None else self.run
        key = case_key(row)
        self.rows[key] = row
        if diagnostics is not None:
            self.diagnostics[key] = json.dumps(diagnostics, default=_json_scalar)
        else:
            self.diagnostics.pop(key, None)

    def link_fields(self, case_name, rel):
        """Link a fields file already written by :func:`write_fields_file` (any rank) at next commit."""
        self.field_links[case_name] = rel

    def table(self):
        keys = sorted(self.rows)
        return np.array([self.rows[k] for k in keys], dtype=CASE_DTYPE)

    def commit(self, complete=False):
        """Atomically (re)write the main file with everything finished so far."""
        self.complete = complete
        atomic_h5(self.path, self._fill)
        # again after every commit: a killed writer may still have been dying when this run opened
        remove_stale_temporaries(self.path)

    def _fill(self, f):
        f.attrs["format"] = FORMAT
        f.attrs["vecontact_version"] = __version__
        f.attrs["git_commit"] = self.runs[self.run]["git_commit"] if self.runs else git_commit()
        f.attrs["job_yaml"] = self.job_yaml
        f.attrs["physics_hash"] = self.physics_hash
        f.attrs["created"] = self.created
        f.attrs["updated"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
        f.attrs["nranks"] = self.nranks
        f.attrs["complete"] = self.complete
        cases = f.create_dataset("cases", data=self.table(), maxshape=(None,))
        cases.attrs["units"] = json.dumps({n: u for n, _, u, _ in COLUMNS})
        cases.attrs["descriptions"] = json.dumps({n: d for n, _, _, d in COLUMNS})
        cases.attrs["status_codes"] = STATUS_CODES
        text = h5py.string_dtype()
        keys = sorted(self.rows)
        f.create_dataset("diagnostics", data=np.array([self.diagnostics.get(k, "") for k in keys], dtype=object),
                         dtype=text)
        f.create_dataset("runs", data=np.array([json.dumps(r) for r in self.runs], dtype=object), dtype=text)
        for name, datasets in self.groups.items():
            g = f.require_group(name)
            for k, v in self.group_attrs[name].items():
                g.attrs[k] = v
            _write_tree(g, datasets)
        if self.field_links:
            g = f.create_group("fields")
            for name, rel in sorted(self.field_links.items()):
                g[name] = h5py.ExternalLink(rel, "/")


def _json_scalar(obj):
    """numpy scalars in diagnostics (np.int64 is not an int to json)."""
    if isinstance(obj, np.generic):
        return obj.item()
    raise TypeError(f"diagnostics: {type(obj).__name__} is not JSON serialisable")


def read_strings(f, name, n=None):
    """A 1-D string dataset as a list of str (absent: n empty strings, or [])."""
    if name not in f:
        return [""] * (n or 0)
    return [s.decode() if isinstance(s, bytes) else str(s) for s in f[name][()]]


def _write_tree(group, tree):
    """Write a nested dict of arrays / dicts; keys starting with '@' become attributes."""
    for k, v in tree.items():
        if k.startswith("@"):
            group.attrs[k[1:]] = v
        elif isinstance(v, dict):
            _write_tree(group.require_group(k), v)
        else:
            group.create_dataset(k, data=np.asarray(v))


def open_for_reading(path):
    """The results file ``path`` open read-only; InputError (key ``results``) if it is missing, not
    HDF5 or not a vecontact results file."""
    if not os.path.isfile(path):
        raise InputError("results", f"file not found: {path}")
    try:
        f = h5py.File(path, "r")
    except OSError:
        raise InputError("results", f"{path} is not an HDF5 file") from None
    if f.attrs.get("format") != FORMAT or "theory" not in f or "cases" not in f:
        f.close()
        raise InputError("results", f"{path} is not a vecontact results file (no format, /theory or /cases)")
    return f


def read_cases(path):
    """The /cases table of a results file as a numpy structured array."""
    with h5py.File(path, "r") as f:
        return f["cases"][()]
