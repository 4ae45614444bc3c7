"""The one PETSc-options parser (vecontact/solver/options.py) and SolverSettings (settings.py): pure,
no PETSc and no MPI needed."""
import dataclasses

import pytest

from vecontact.errors import InputError
from vecontact.solver.options import OptionError, parse, solver_items, split_argv
from vecontact.solver.settings import SolverSettings, gmres_restart

CLI_OURS = {"--quiet", "--no-plot", "-o", "--output", "-h", "--help", "--version"}


def test_forms_agree():
    """A mapping, a string and command-line tokens give the same options."""
    text = "-snes_type vinewtonrsls -ksp_rtol 0.001 -snes_monitor -ksp_divtol -1e-3 -vc_restart_max 60"
    want = {"snes_type": "vinewtonrsls", "ksp_rtol": "0.001", "snes_monitor": None, "ksp_divtol": "-1e-3",
            "vc_restart_max": "60"}
    assert parse(text) == want
    assert parse(text.split()) == want
    assert parse(["-snes_type vinewtonrsls", "-ksp_rtol 0.001 -snes_monitor", "-ksp_divtol", "-1e-3",
                  "-vc_restart_max 60"]) == want
    assert parse({"snes_type": "vinewtonrsls", "-ksp_rtol": 1e-3, "snes_monitor": None, "ksp_divtol": "-1e-3",
                  "vc_restart_max": 60}) == want
    _, tokens = split_argv(["run", "job.yaml"] + text.split(), CLI_OURS)
    assert parse(tokens) == want
    assert parse(None) == {} and parse("") == {} and parse([]) == {}


@pytest.mark.parametrize("text, want", [
    ("-a -5 -b", {"a": "-5", "b": None}),                 # a negative number is a value
    ("-a +.5e+3", {"a": "+.5e+3"}),
    ("-a -1. -b 2", {"a": "-1.", "b": "2"}),
    ("-a -inf", {"a": None, "inf": None}),               # not a decimal number: a name
    ("-a -b -c x", {"a": None, "b": None, "c": "x"}),     # flags
    ("-ksp_type gmres -ksp_type bcgs", {"ksp_type": "bcgs"}),   # the last one wins
    ("-a true -b false", {"a": "true", "b": "false"}),
])
def test_value_rules(text, want):
    assert parse(text) == want


def test_mapping_values():
    got = parse({"a": True, "b": False, "c": None, "d": "", "e": 3, "-f": "x"})
    assert got == {"a": "true", "b": "false", "c": None, "d": None, "e": "3", "f": "x"}


@pytest.mark.parametrize("value, problem", [
    ("gmres -ksp_type", "expected an option"),
    ("-1e-3", "expected an option"),
    ("--ksp_rtol 1", "bad option name"),
    ("-ksp_rtol=1e-3", "bad option name"),
    ({"a b": 1}, "bad option name"),
    ({"": 1}, "bad option name"),
    ({"ksp_rtol": [1, 2]}, "single value"),
    (3, "mapping"),
    ("-vc_restart_max 6e1", "integer"),
    ("-vc_restart_max", "needs a value"),
    ("-vc_lin_rtol x", "number"),
    ("-vc_lin_rtol 2", "outside"),
    ("-vc_lin_rtol nan", "finite"),
    ("-vc_contact_step sideways", "auto, contact, free"),
    ("-vc_no_such_knob 1", "unknown solver setting"),
    ("-contact_step free", "renamed -vc_contact_step"),
    ("-contact_step_area 0.2", "renamed -vc_contact_step_area"),
    ("-snes_type vinewtonssls", "removed"),
    ("-vc_recycle_vectors 0", "removed with the Krylov recycling"),
    ("-vc_contact_step_large_n 4096", "removed: -vc_contact_step_area_large applies by the range of"),
    ("-vc_contact_step_range_max 4e5", "replaced by -vc_contact_step_modulus_large"),
    ({"vc_recycle_cost": 4}, "lost in wall time"),
    ("-vc_smooth_omega 0.7", "Chebyshev steps now, -vc_smooth_ratio"),
    ("-vc_contact_step_range_min 5e4", "replaced by -vc_contact_step_modulus_max"),
    ("-snes_rtol 1e-2", "-snes_rtol: no effect: .* set numerics.tolerance"),
    ({"snes_atol": 1e3}, "-snes_atol: no effect"),
    ("-snes_stol 1e-10", "-snes_stol: no effect"),
    ("-snes_divergence_tolerance 1e4", "-snes_divergence_tolerance: no effect: .* -snes_max_it Newton steps"),
    ({"snes_max_funcs": 100}, r"-snes_max_funcs: no effect: .*\(numerics.max_iterations\)"),
])
def test_errors_name_the_key(value, problem):
    """Bad options: an OptionError that is an InputError (one line, the caller's key) and a ValueError."""
    with pytest.raises(OptionError, match=problem) as err:
        parse(value, "numerics.petsc")
    assert isinstance(err.value, InputError) and isinstance(err.value, ValueError)
    assert err.value.key == "numerics.petsc" and "\n" not in str(err.value)


def test_split_argv():
    argv = ["run", "job.yaml", "-ksp_divtol", "-1e-3", "--quiet", "-o", "out.h5", "-snes_monitor",
            "-ksp_type", "gmres", "--no-plot"]
    known, tokens = split_argv(argv, CLI_OURS)
    assert known == ["run", "job.yaml", "--quiet", "-o", "out.h5", "--no-plot"]
    assert tokens == ["-ksp_divtol", "-1e-3", "-snes_monitor", "-ksp_type", "gmres"]


def test_solver_items_split_ours_from_petsc():
    petsc, ours = solver_items(parse("-ksp_type bcgs -vc_restart_max 60"))
    assert petsc == {"ksp_type": "bcgs"} and ours == {"vc_restart_max": "60"}


# ---------------------------------------------------------------------------------------- settings
def test_settings_options_override_fields():
    s = SolverSettings().with_options(parse("-vc_restart_max 60 -vc_lin_rtol 0.05 -vc_contact_step free "
                                            "-ksp_type bcgs"))
    assert (s.restart_max, s.lin_rtol, s.contact_step) == (60, 0.05, "free")
    assert isinstance(s.restart_max, int)
    base = SolverSettings(smooth_sweeps=2)
    assert base.with_options({}) == base and base.with_options(parse("-vc_coarse_levels 1")).smooth_sweeps == 2
    with pytest.raises(dataclasses.FrozenInstanceError):
        s.lin_rtol = 0.2


def test_settings_check_their_ranges():
    for bad in (dict(lin_rtol=0.0), dict(restart_max=1.5), dict(contact_step_area=1.2),
                dict(bearing_area_min=0.5, bearing_area_max=0.4), dict(smooth_ratio=0.5),
                dict(coarse_levels=True)):
        with pytest.raises(ValueError):
            SolverSettings(**bad)


def test_step_area_by_modulus_range():
    """contact_step_area_large where the modulus range exceeds contact_step_modulus_large; else
    contact_step_area_small where it is at most contact_step_modulus_max on grids of at least
    contact_step_min_n.  The paper's compound, the modulus range by N and v: 512^2 10 m/s (111), 100 m/s
    (272); 1024^2 0.01 m/s (6.37), 1 m/s (54), 10 m/s (149), 100 m/s (338); 2048^2 0.1 m/s (25.3), 1 m/s
    (74.2), 30 m/s (289), 100 m/s (407); 4096^2 0.01 m/s (11.9), 0.1 m/s (35.2), 1 m/s (101), 3 m/s
    (161), 10 m/s (253), 30 m/s (356) [RESULTS.md]."""
    s = SolverSettings()
    assert (s.contact_step_area, s.contact_step_area_large, s.contact_step_modulus_large) == (0.3, 0.2, 300.0)
    assert (s.contact_step_area_small, s.contact_step_modulus_max, s.contact_step_min_n) == (0.6, 60.0, 1024)
    assert s.step_area(101, 4096) == s.step_area(74.2, 2048) == s.step_area(60.01, 4096) == 0.3
    assert s.step_area(4.74, 512) == s.step_area(111, 512) == s.step_area(272, 512) == s.step_area(149, 1024) == 0.3
    assert s.step_area(161, 4096) == s.step_area(253, 4096) == s.step_area(289, 2048) == s.step_area(300, 8192) == 0.3
    assert s.step_area(300.01, 512) == s.step_area(338, 1024) == s.step_area(407, 2048) == s.step_area(356, 4096) == 0.2
    assert s.step_area(6.37, 1024) == s.step_area(54, 1024) == s.step_area(25.3, 2048) == 0.6
    assert s.step_area(11.9, 4096) == s.step_area(35.2, 4096) == s.step_area(1.0, 4096) == s.step_area(60.0, 8192) == 0.6
    assert SolverSettings(contact_step_modulus_large=400).step_area(356, 4096) == 0.3
    assert SolverSettings(contact_step_modulus_large=50).step_area(54, 1024) == 0.2
    assert SolverSettings(contact_step_min_n=512).step_area(40.0, 512) == 0.6
    assert SolverSettings(contact_step_modulus_max=0.0).step_area(1.0, 4096) == 0.3
    assert s.widest_step_area(4096) == 0.6 and s.widest_step_area(512) == 0.3
    # modulus_max below 1: the small-area rule never applies, so no wider set (as before session 66)
    assert SolverSettings(contact_step_modulus_max=0.0).widest_step_area(4096) == 0.3


def test_cycle_cap_by_stiffness_range():
    """cycle_after_cap_large where the stiffness range exceeds cycle_range_max: the paper's compound
    at 10 m/s on 2048^2 (2.84e5) and 4096^2 (7.31e5), at 1 m/s on 4096^2 (2.93e5); not at 1024^2, 10 m/s
    (1.08e5) nor 2048^2, 1 m/s (1.07e5), where early cycles lost at 41 % [RESULTS.md]."""
    s = SolverSettings()
    assert (s.cycle_after_cap, s.cycle_after_cap_large, s.cycle_range_max) == (80, 40, 1.5e5)
    assert s.cycle_cap(1.0) == s.cycle_cap(1.08e5) == s.cycle_cap(1.5e5) == 80
    assert s.cycle_cap(1.5001e5) == s.cycle_cap(2.84e5) == s.cycle_cap(7.31e5) == 40
    assert SolverSettings(cycle_range_max=1e6).cycle_cap(7.31e5) == 80
    assert SolverSettings(cycle_after_cap_large=80).cycle_cap(7.31e5) == 80


def test_restart_lengths():
    """The cap, unless the basis exceeds the memory budget: 4096^2 on 2 ranks (8 Mi local points,
    3 GB): GMRES 43, FGMRES 21; never below restart_min.  The contact-set steps' inner FGMRES has the
    same budget: 18 % of that grid (1.5 Mi local points) gets restart 100 (61 with the 1.5 GB of session 19)."""
    s = SolverSettings()
    n = 4096 * 2048
    assert s.restart(n, vectors=1) == 43 and s.restart(n, vectors=2) == 21
    assert s.restart(1000) == s.restart_max == 120
    assert s.restart(10 ** 10) == s.restart_min == 10
    assert s.inner_restart(1000) == s.inner_restart_max == 100
    assert s.inner_restart(n) == gmres_restart(n, 3e9, 2, 100, 10) == 21
    assert s.inner_restart(int(0.18 * n)) == 100 and s.inner_restart(int(0.27 * n)) == 81
