"""The resolved job as frozen values: :class:`Job` and its sections :class:`Surface`,
:class:`Material`, :class:`Sweep`, :class:`Theory`, :class:`Numerics`.

:mod:`vecontact.job` validates a YAML job and builds these. ``Job.to_dict()`` gives the resolved
job back as the plain dict that is stored as YAML in every results file (``job_yaml``) and hashed
for restarts, with the same keys in the same order as ever; ``Job.from_dict()`` reads such a dict
(a results file's stored job). Lists are tuples here (a validated job does not change). The
derived quantities have one home each: :attr:`Surface.length`, :meth:`Surface.grid`,
:meth:`Surface.realisations`, :meth:`Material.modulus` (cached: a table file is read once).

Units are SI: wavevectors in 1/m, lengths in m, C(q) in m^4, moduli and pressures in Pa, times
in s, velocities in m/s.
"""
import math
from dataclasses import dataclass, field, fields
from typing import Optional, Union

#: Keys of the resolved ``surface`` section per spectrum, in their stored order.
SURFACE_KEYS = {
    "self-affine": ("spectrum", "amplitudes", "q0", "qr", "q1", "hurst", "C0", "hrms", "null_band", "seeds",
                    "grid"),
    "file": ("spectrum", "amplitudes", "file", "dataset", "length", "source", "seeds", "null_band"),
    "psd": ("spectrum", "amplitudes", "file", "dimension", "columns", "sha256", "length", "q0", "q1",
            "null_band", "seeds", "table", "grid"),
}
#: Keys of the resolved ``material`` section per model, in their stored order.
MATERIAL_KEYS = {
    "elastic": ("model", "nu", "E0"),
    "sls": ("model", "nu", "E0", "Einf", "tau"),
    "havriliak-negami": ("model", "nu", "E0", "Einf", "tau", "alpha", "beta"),
    "prony": ("model", "nu", "E0", "terms"),
    "table": ("model", "nu", "file", "frequency_unit", "modulus_unit", "columns", "vertical_shift", "wlf"),
}
#: Keys stored only when they have a value (C0 or hrms; an instrument file's ``source``; ``fft_planner``,
#: so that the stored text of jobs written before it existed stays the same).
_ONLY_WITH_VALUE = {"C0", "hrms", "source", "fft_planner"}
#: Stored key -> attribute, where they differ.
_ATTRIBUTE = {"length": "period"}


# --------------------------------------------------------------------------------------------
# the grid rule
def nyquist_points(q0, q1, null_band):
    """The grid size (a real number) whose Nyquist wavevector pi N / L is null_band q1, with
    L = 2 pi / q0 (docs/conventions.md §2): N = 2 null_band q1 / q0."""
    return 2.0 * null_band * q1 / q0


def fft_size(n_min):
    """The smallest N >= n_min of the form 2^a, 3 2^a or 5 2^a (a >= 1): even, a fast FFT size,
    and halvable for the solver's coarse grids."""
    best = None
    for m in (1, 3, 5):
        n = 2 * m
        while n < n_min:
            n *= 2
        best = n if best is None else min(best, n)
    return best


def grid_points(spectrum, q0, q1, null_band):
    """Grid points per side of a generated surface at cut-off q1 (1/m): N = 2 null_band q1 / q0
    (self-affine; the job checks that it is an integer), or the FFT size at or above it (psd)."""
    n = nyquist_points(q0, q1, null_band)
    return fft_size(n * (1 - 1e-12)) if spectrum == "psd" else int(round(n))


# --------------------------------------------------------------------------------------------
# dict <-> frozen values
def _frozen(value, memo):
    """Lists (also inside dicts) as tuples; one list object gives one tuple object, so that what
    the dict shared (one seeds list for several q1) stays shared."""
    if isinstance(value, list):
        if id(value) not in memo:
            memo[id(value)] = (tuple(_frozen(v, memo) for v in value), value)   # value kept: ids stay unique
        return memo[id(value)][0]
    if isinstance(value, dict):
        return {k: _frozen(v, memo) for k, v in value.items()}
    return value


def _plain(value, memo):
    """The inverse of :func:`_frozen`: tuples as lists, a shared tuple as one shared list (the stored
    YAML writes it once, as an anchor); empty tuples (one object in Python) as separate lists."""
    if isinstance(value, tuple):
        if not value:
            return []
        if id(value) not in memo:
            memo[id(value)] = ([_plain(v, memo) for v in value], value)
        return memo[id(value)][0]
    if isinstance(value, dict):
        return {k: _plain(v, memo) for k, v in value.items()}
    return value


class _Section:
    """A section of the job. Its resolved dict holds :meth:`stored_keys` in order (``length`` is the
    attribute ``period``; ``grid`` is derived, :meth:`Surface.grids`); a key of ``_ONLY_WITH_VALUE``
    only when it has a value. ``memo``: shared by the sections of one job (see :func:`_frozen`)."""

    def stored_keys(self):
        """The keys of this section's resolved dict, in their stored order."""
        return tuple(f.name for f in fields(self) if f.init)

    def to_dict(self, memo=None):
        """The section's resolved dict."""
        memo = {} if memo is None else memo
        out = {}
        for key in self.stored_keys():
            value = self.grids() if key == "grid" else getattr(self, _ATTRIBUTE.get(key, key))
            if value is not None or key not in _ONLY_WITH_VALUE:
                out[key] = _plain(value, memo)
        return out

    @classmethod
    def from_dict(cls, d, memo=None):
        """The section from its resolved dict; keys it does not hold (``grid``: derived) are skipped,
        missing ones take the defaults (results files of earlier versions)."""
        memo = {} if memo is None else memo
        names = {f.name for f in fields(cls) if f.init}
        given = {_ATTRIBUTE.get(k, k): v for k, v in d.items()}
        return cls(**{name: _frozen(v, memo) for name, v in given.items() if name in names})


# --------------------------------------------------------------------------------------------
# the sections
@dataclass(frozen=True)
class Surface(_Section):
    """The rough substrate: its spectrum and the realisations solved on (``surface`` section).

    ``spectrum`` decides which fields apply: self-affine (q0, qr, q1, hurst, C0 or hrms), psd (a
    measured C(q) table: file, dimension, columns, sha256, period, q0, q1, table) or file (heights
    read from a file: file, dataset, period, source)."""
    spectrum: str = "self-affine"               # self-affine, psd or file
    amplitudes: str = "fixed"                   # Fourier amplitudes: fixed (|h_q|^2 = C (2 pi / L)^2) or gaussian
    q0: Optional[float] = None                  # smallest wavevector 2 pi / L (1/m); psd: from the period
    qr: Optional[float] = None                  # roll-off wavevector (1/m), self-affine
    q1: tuple = ()                              # cut-off wavevectors (1/m), sorted; () for a height file
    hurst: Optional[float] = None               # Hurst exponent H (dimensionless), self-affine
    C0: Optional[float] = None                  # plateau of C(q) (m^4), self-affine (or hrms)
    hrms: Optional[float] = None                # rms height (m) at the largest q1, self-affine (or C0)
    null_band: Optional[float] = None           # grid resolves wavevectors up to null_band q1 (dimensionless)
    seeds: Union[tuple, dict] = (1,)            # realisations: one tuple, or {repr(q1): tuple}; see realisations()
    file: Optional[str] = None                  # absolute path of the C(q) table (psd) or height file (file)
    dataset: Optional[str] = None               # HDF5 dataset or instrument channel of the height file
    period: Optional[float] = None              # key "length" (m): a height file's period, the psd system's side
    source: Optional[dict] = None               # provenance of an instrument scan (format, channel, crop...)
    dimension: Optional[int] = None             # psd: 2 for C(q) in m^4, 1 for a line-scan C1D(q) in m^3
    columns: Optional[tuple] = None             # psd: the table's (q, C) columns (index or name), None: first two
    sha256: Optional[str] = None                # psd: SHA-256 of the table file
    table: Optional[dict] = None                # psd: rows, q_min, q_max (1/m), hrms (m) of the table

    @property
    def length(self):
        """The period L of the surface (m): the height file's, else 2 pi / q0 (docs/conventions.md §1)."""
        return self.period if self.spectrum == "file" else 2.0 * math.pi / self.q0

    def grid(self, q1=None):
        """Grid points per side N of the cases at cut-off q1 (1/m): :func:`grid_points` for a
        generated surface; for a height file its N, read from the file (q1 not needed)."""
        if self.spectrum == "file":
            from vecontact.io.surfaces import file_grid_size
            return file_grid_size(self.file, self.dataset)
        return grid_points(self.spectrum, self.q0, q1, self.null_band)

    def grids(self):
        """{repr(float(q1)): N} for every q1 (the resolved job's ``grid``)."""
        return {repr(float(q1)): self.grid(q1) for q1 in self.q1}

    def realisations(self, q1):
        """The surface realisations (seeds, a tuple of int) at cut-off q1 (1/m)."""
        return self.seeds if isinstance(self.seeds, tuple) else self.seeds[repr(float(q1))]

    def stored_keys(self):
        return SURFACE_KEYS[self.spectrum]


@dataclass(frozen=True)
class Material(_Section):
    """The rubber's linear viscoelastic modulus E(omega) (``material`` section; docs/conventions.md
    §3). ``model`` decides which fields apply (see :data:`MATERIAL_KEYS`)."""
    model: str = "elastic"                      # elastic, sls, prony, havriliak-negami or table
    nu: float = 0.5                             # Poisson ratio (dimensionless)
    E0: Optional[float] = None                  # relaxed (rubbery) modulus E(0) (Pa); elastic: the modulus
    Einf: Optional[float] = None                # glassy modulus E(infinity) (Pa), sls and havriliak-negami
    tau: Optional[float] = None                 # relaxation time (s), sls and havriliak-negami
    alpha: Optional[float] = None               # Havriliak-Negami width exponent (dimensionless)
    beta: Optional[float] = None                # Havriliak-Negami asymmetry exponent (dimensionless)
    terms: Optional[tuple] = None               # prony: ((dE in Pa, tau in s), ...)
    file: Optional[str] = None                  # table: absolute path of the master curve (omega, E', E'')
    frequency_unit: str = "rad/s"               # table: unit of its frequency column (rad/s or Hz)
    modulus_unit: str = "Pa"                    # table: unit of its modulus columns (Pa, kPa, MPa, GPa)
    columns: Optional[tuple] = None             # table: its (frequency, E', E'') columns, None: the first three
    vertical_shift: float = 1.0                 # table: factor bT on E' and E'' (dimensionless)
    wlf: Optional[dict] = None                  # table: WLF shift {C1, C2 (K), T_ref (K or C), T}, or None
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def modulus(self):
        """The modulus model E(omega) (:mod:`vecontact.physics.modulus`), built once per Material (a
        table file is read once)."""
        if "modulus" not in self._cache:
            from vecontact.physics.modulus import make_modulus
            self._cache["modulus"] = make_modulus(self.to_dict())
        return self._cache["modulus"]

    def stored_keys(self):
        return MATERIAL_KEYS.get(self.model) or super().stored_keys()


@dataclass(frozen=True)
class AreaRange:
    """Pressures chosen per (q1, v) from the theory so that A/A0 runs geometrically over
    [area_min, area_max] in ``num`` steps (the sweep's ``pressure: {area_min, area_max, num}``)."""
    area_min: float                             # smallest contact area fraction A/A0 (dimensionless)
    area_max: float                             # largest contact area fraction A/A0 (dimensionless)
    num: int                                    # pressures per (q1, v)


@dataclass(frozen=True)
class Sweep(_Section):
    """The sliding velocities and nominal pressures of the cases (``sweep`` section)."""
    velocity: tuple = ()                        # sliding velocities v (m/s), sorted
    pressure: Union[tuple, AreaRange] = ()      # nominal pressures sigma0 (Pa), or an AreaRange

    def to_dict(self, memo=None):
        memo = {} if memo is None else memo
        p = self.pressure
        return {"velocity": _plain(self.velocity, memo),
                "pressure": {"area_min": p.area_min, "area_max": p.area_max, "num": p.num}
                if isinstance(p, AreaRange) else _plain(p, memo)}

    @classmethod
    def from_dict(cls, d, memo=None):
        memo = {} if memo is None else memo
        p = d.get("pressure", ())
        return cls(velocity=_frozen(d.get("velocity", []), memo),
                   pressure=AreaRange(**p) if isinstance(p, dict) else _frozen(p, memo))


@dataclass(frozen=True)
class Theory(_Section):
    """Persson's theory: S(q) and the quadrature (``theory`` section; docs/conventions.md §5)."""
    gamma: float = 0.5                          # S(q) = gamma + (1 - gamma) P(q)^2 (dimensionless)
    nq: Optional[int] = None                    # wavevector nodes per decade, None: the converged default
    nphi: Optional[int] = None                  # angular nodes on [0, pi/2], None: the converged default


@dataclass(frozen=True)
class Numerics(_Section):
    """The exact solver and what it stores (``numerics`` section; docs/solver.md)."""
    enabled: bool = False                       # solve every case numerically (else: theory only)
    solver: str = "snes"                        # snes (any material) or pk (Polonsky-Keer, elastic only)
    tolerance: float = 1e-8                     # relative residual of the solve (dimensionless)
    petsc: dict = field(default_factory=dict)   # PETSc options {name without '-': value or None}
    fields: tuple = ()                          # fields stored per case: pressure, gap, displacement, contact
    downsample: int = 1                         # every downsample-th grid point of the stored fields
    ranks_per_case: Union[str, int] = "auto"    # ranks solving one case together, or auto (by memory and case count)
    coarse: bool = True                         # coarse-grid start of each solve
    max_iterations: Optional[int] = None        # Newton steps at most, None: the solver's default
    threads: int = 1                            # FFTW threads per rank
    fft_planner: Optional[str] = None           # FFTW planner: measure (None, the default) or patient


_SECTIONS = (("surface", Surface), ("material", Material), ("sweep", Sweep), ("theory", Theory),
             ("numerics", Numerics))


@dataclass(frozen=True)
class Job:
    """A validated job, every default filled in and every path absolute (built by
    :func:`vecontact.job.load` and :func:`vecontact.job.resolve`)."""
    output: str                                 # absolute path of the results file (.h5)
    surface: Surface
    material: Material
    sweep: Sweep
    theory: Theory = field(default_factory=Theory)
    numerics: Numerics = field(default_factory=Numerics)

    def to_dict(self):
        """The resolved job as a plain dict (stored as YAML in results files; hashed for restarts)."""
        memo = {}
        out = {"output": self.output}
        for name, _ in _SECTIONS:
            out[name] = getattr(self, name).to_dict(memo)
        return out

    @classmethod
    def from_dict(cls, d):
        """A job from its resolved dict (e.g. ``yaml.safe_load`` of a results file's ``job_yaml``);
        not validated again (its files need not exist), missing sections and keys take their
        defaults."""
        memo = {}
        return cls(output=d.get("output"),
                   **{name: kind.from_dict(d.get(name) or {}, memo) for name, kind in _SECTIONS})
