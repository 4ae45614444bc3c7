"""The one parser of PETSc options: command line (cli.py), job (``numerics.petsc``, job.py) and solver.

Rules, the same everywhere:

* Forms: a mapping {name: value} (YAML, Python), a string ``"-name value -flag"``, or a list of such
  strings (the command line's tokens, a YAML list).  A name is given with or without one leading '-'.
* Names: letters, digits and underscores, not starting with a digit (``-ksp_rtol=1e-3`` and
  ``--ksp_rtol`` are errors).
* In a string or list, a token that starts with '-' is a name unless it is a number
  (``[+-]digits[.digits][e[+-]digits]``): ``-ksp_divtol -1e-3`` sets ksp_divtol to "-1e-3".  The token
  after a name is its value unless it is itself a name; a name without a value is a flag.
* Values are strings; a flag is None (PETSc reads it as true).  In a mapping, None or "" is a flag,
  True/False become "true"/"false", numbers str(value); lists and mappings are errors.
* A repeated name: the last value wins (as in PETSc).
* ``-vc_<field>`` sets a SolverSettings field (settings.py) and is checked here; a removed or renamed
  option of an old job is an error naming its replacement (RETIRED), and so is a PETSc option the
  solver overrides, which would do nothing (NO_EFFECT: -snes_rtol, -snes_atol, -snes_stol,
  -snes_divergence_tolerance, -snes_max_funcs).

Errors are OptionError: an InputError (one line naming the caller's key) and a ValueError.
"""
from __future__ import annotations

import re

from vecontact.errors import InputError
from vecontact.solver.settings import PREFIX, SolverSettings

__all__ = ["parse", "split_argv", "solver_items", "OptionError", "RETIRED", "NO_EFFECT"]

_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*\Z")
_NUMBER = re.compile(r"[+-]?(\d+\.?\d*|\.\d+)([eE][+-]?\d+)?\Z")

_RECYCLING = "removed with the Krylov recycling of the contact-set steps (it lost in wall time, benchmarks/RESULTS.md)"
# (name, value or None for any value) -> what to use instead; one line each
RETIRED = {
    ("contact_step", None): f"renamed -{PREFIX}contact_step",
    ("contact_step_area", None): f"renamed -{PREFIX}contact_step_area (-{PREFIX}contact_step_area_large "
                                 f"above -{PREFIX}contact_step_modulus_large)",
    (f"{PREFIX}contact_step_large_n", None): f"removed: -{PREFIX}contact_step_area_large applies by the "
                                             f"range of |E(q_x v)|, -{PREFIX}contact_step_modulus_large",
    (f"{PREFIX}contact_step_range_max", None): f"replaced by -{PREFIX}contact_step_modulus_large (300): "
                                               f"contact_step_area_large applies by the range of |E(q_x v)|, "
                                               f"not of the stiffness (benchmarks/RESULTS.md)",
    (f"{PREFIX}contact_step_range_min", None): f"replaced by -{PREFIX}contact_step_modulus_max (60): "
                                               f"contact_step_area_small applies by the range of |E(q_x v)|, "
                                               f"not of the stiffness (benchmarks/RESULTS.md)",
    ("snes_type", "vinewtonssls"): "removed (it did not converge with the compliance preconditioner); "
                                   "use the default newtonls or vinewtonrsls",
    (f"{PREFIX}recycle_vectors", None): _RECYCLING,
    (f"{PREFIX}recycle_memory", None): _RECYCLING,
    (f"{PREFIX}recycle_cost", None): _RECYCLING,
    (f"{PREFIX}smooth_omega", None): f"removed with the damped-Jacobi smoothing: its sweeps take Chebyshev "
                                     f"steps now, -{PREFIX}smooth_ratio (benchmarks/RESULTS.md)",
}


_OWN_TEST = ("no effect: the solver's own scale-free test decides convergence (docs/solver.md, "
             "\"Convergence\"); set numerics.tolerance, or solve_contact(..., tolerance=...)")
_STEPS = ("no effect: the solver's own test ends a solve (docs/solver.md, \"Convergence\"): converged, or "
          "recorded as failed with its residual after -snes_max_it Newton steps (numerics.max_iterations)")
# PETSc options the solver overrides, which would silently do nothing -> why, one line each (PETSc's
# default convergence test reads them, and the solver's replaces it)
NO_EFFECT = dict(dict.fromkeys(("snes_rtol", "snes_atol", "snes_stol"), _OWN_TEST),
                 snes_divergence_tolerance=_STEPS, snes_max_funcs=_STEPS)


class OptionError(InputError, ValueError):
    """A bad PETSc option: one line for the command line, a ValueError for library callers."""


def is_name(token):
    """True when the command-line token starts an option (a '-' that does not start a number)."""
    return token.startswith("-") and not _NUMBER.match(token)


def parse(value, key="petsc_options"):
    """Options in any of the forms above -> {name without '-': value string or None}, checked.

    ``key`` names the source in errors (``numerics.petsc``)."""
    if value is None:
        items = []
    elif isinstance(value, dict):
        items = [(str(k), _mapping_value(k, v, key)) for k, v in value.items()]
    elif isinstance(value, (str, list, tuple)):
        items = _tokens(value, key)
    else:
        raise OptionError(key, "must be a mapping {option: value} or a list of options")
    out = {}
    for name, v in items:
        name = name[1:] if name.startswith("-") else name
        if not _NAME.match(name):
            raise OptionError(key, f"bad option name {name!r}")
        out[name] = v
    _check(out, key)
    return out


def split_argv(argv, ours):
    """Command-line arguments -> (our arguments, PETSc tokens).  A single-dash name of more than one
    letter that is not in ``ours`` starts a PETSc option; its value follows by the rules above."""
    known, petsc, i = [], [], 0
    while i < len(argv):
        a = argv[i]
        if is_name(a) and not a.startswith("--") and a not in ours and len(a) > 2:
            petsc.append(a)
            if i + 1 < len(argv) and not is_name(argv[i + 1]):
                petsc.append(argv[i + 1])
                i += 1
        else:
            known.append(a)
        i += 1
    return known, petsc


def solver_items(options):
    """(PETSc's entries, vecontact's ``-vc_`` entries) of a parsed options dict."""
    petsc = {k: v for k, v in options.items() if not k.startswith(PREFIX)}
    ours = {k: v for k, v in options.items() if k.startswith(PREFIX)}
    return petsc, ours


def _mapping_value(name, v, key):
    if v is None or v == "":
        return None
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (dict, list, tuple, set)):
        raise OptionError(key, f"{name}: expected a single value, got {v!r}")
    return str(v)


def _tokens(value, key):
    toks = []
    for s in [value] if isinstance(value, str) else value:
        toks.extend(str(s).split())
    items, i = [], 0
    while i < len(toks):
        tok = toks[i]
        if not is_name(tok):
            raise OptionError(key, f"expected an option -name, got {tok!r}")
        v = None
        if i + 1 < len(toks) and not is_name(toks[i + 1]):
            v = toks[i + 1]
            i += 1
        items.append((tok, v))
        i += 1
    return items


def _check(options, key):
    for (name, val), why in RETIRED.items():
        if name in options and (val is None or options[name] == val):
            raise OptionError(key, f"-{name}{'' if val is None else ' ' + val}: {why}")
    for name, why in NO_EFFECT.items():
        if name in options:
            raise OptionError(key, f"-{name}: {why}")
    try:
        SolverSettings().with_options(options)
    except ValueError as exc:
        raise OptionError(key, str(exc)) from None
