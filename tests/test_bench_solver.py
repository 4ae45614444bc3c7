"""benchmarks/solver.py's summary: the headline ratios, and the side-by-side BLAS comparison (--blas)."""
import os

import pytest

from reference.bench import ROOT, load


@pytest.fixture(scope="module")
def bench():
    return load("solver")


def _snes(N, v, target, pairs, seconds, t_pair, overhead, blas, pair_seconds=None):
    return dict(kind="snes", N=N, v=v, target=target, pairs=pairs, seconds=seconds, t_pair=t_pair,
                overhead=overhead, converged=True, oracle_converged=True, blas=blas, pair_seconds=pair_seconds)


def test_summary_without_blas(bench):
    recs = [_snes(1024, 10, 0.05, 100.0, 3.0, 0.02, 2.5, None, pair_seconds=2.5),
            _snes(2048, 10, 0.05, 200.0, 12.0, 0.04, 3.5, None, pair_seconds=10.0),
            _snes(512, 10, 0.05, 80.0, 1.0, 0.005, 1.5, None, pair_seconds=0.5)]
    out = bench.summarise(recs)
    assert out["time_per_pair_ratio"] == pytest.approx(1.5, rel=1e-12)          # 12 / (200 * 0.04)
    assert out["time_per_pair_ratio_median"] == pytest.approx(1.5, rel=1e-12)   # 1.5 and 1.5 at N >= 1024
    # the two factors of the ratio (N >= 1024 only): outside the pairs 3/2.5 and 12/10, inside 2.5/2, 10/8
    assert out["solve_over_pairs_max"] == pytest.approx(1.2, rel=1e-12)
    assert out["pair_in_solve_ratio_max"] == pytest.approx(1.25, rel=1e-12)
    assert out["overhead_max"] == 3.5 and "blas" not in out
    assert out["pairs_growth"] == pytest.approx(200.0 / 80.0, rel=1e-12)
    assert out["time_per_pair_ratio_paced"] is None       # no case timed its own raw pair


def test_summary_paced_by_each_case_raw_pair(bench):
    """time_per_pair_ratio_paced divides each case by the raw pair timed right after it (N >= 1024; a case
    without one is left out of it, not of time_per_pair_ratio)."""
    recs = [dict(_snes(1024, 10, 0.05, 100.0, 3.0, 0.02, 2.5, None), t_pair_case=0.025),
            dict(_snes(2048, 10, 0.05, 200.0, 12.0, 0.04, 3.5, None), t_pair_case=0.05),
            dict(_snes(2048, 0.01, 0.05, 100.0, 5.0, 0.04, 3.5, None), t_pair_case=None),
            dict(_snes(512, 10, 0.05, 80.0, 1.0, 0.005, 1.5, None), t_pair_case=0.001)]
    out = bench.summarise(recs)
    assert out["time_per_pair_ratio"] == pytest.approx(1.5, rel=1e-12)             # 3/(100*0.02), 12/(200*0.04)
    assert out["time_per_pair_ratio_paced"] == pytest.approx(1.2, rel=1e-12)       # 3/(100*0.025), 12/(200*0.05)
    assert out["time_per_pair_ratio_paced_median"] == pytest.approx(1.2, rel=1e-12)


def test_overhead_counts_only_converged_oracles(bench):
    """An oracle stopped at its cap gives an upper bound on the overhead, listed apart; --no-oracle gives
    none; neither touches all_converged, which is about the solves of the cases."""
    capped = dict(_snes(2048, 10, 0.6, 400.0, 8.0, 0.02, 1.1, None), oracle_converged=False)
    skipped = dict(_snes(1024, 0.01, 0.05, 90.0, 1.0, 0.01, None, None), oracle_converged=None)
    out = bench.summarise([_snes(1024, 10, 0.05, 100.0, 3.0, 0.02, 2.5, None), capped, skipped])
    assert out["overhead_max"] == 2.5 and out["overhead_cases"] == "1 of 3"
    assert out["overhead_bounds"] == [dict(N=2048, v=10, target=0.6, overhead_below=1.1)]
    assert out["all_converged"] is True
    out = bench.summarise([skipped])
    assert out["overhead_max"] is None and out["overhead_bounds"] == []
    not_run = dict(skipped, oracle_iterations=None, oracle_pairs=None)
    assert bench._oracle_text(not_run) == " oracle not run, overhead n/a"
    assert "upper bound" in bench._oracle_text(dict(capped, oracle_iterations=2000, oracle_pairs=364.0))


def test_overhead_against_a_restarted_oracle_is_a_lower_bound(bench):
    """An oracle that restarted (its basis past --oracle-memory) took more iterations than the
    unrestarted one: its overhead is a lower bound, counted in the max and listed; records without
    oracle_restart (before session 63) are taken as they are."""
    full = dict(_snes(1024, 10, 0.3, 548.0, 4.0, 0.005, 2.08, None), oracle_iterations=131, oracle_restart=2000)
    short = dict(_snes(8192, 10, 0.05, 1015.2, 730.0, 0.84, 1.68, None), oracle_iterations=300,
                 oracle_restart=250)
    old = dict(_snes(2048, 10, 0.3, 875.4, 35.0, 0.028, 1.55, None), oracle_iterations=280)
    out = bench.summarise([full, short, old])
    assert out["overhead_max"] == 2.08 and out["overhead_cases"] == "3 of 3"
    assert out["overhead_restarted"] == [dict(N=8192, v=10, target=0.05, overhead_at_least=1.68)]
    text = bench._oracle_text(dict(short, oracle_pairs=604.0))
    assert "restarted every 250: a lower bound" in text
    assert "restarted" not in bench._oracle_text(dict(full, oracle_pairs=264.0))
    assert "restarted" not in bench._oracle_text(dict(old, oracle_pairs=564.0))


def test_summary_compares_blas_side_by_side(bench, capsys):
    lib = "/opt/openblas"
    recs = [dict(kind="fft", N=2048, t_pair=0.04, blas="reference"),
            dict(_snes(2048, 10, 0.05, 200.0, 12.0, 0.04, 3.5, "reference"), blas_lib="/usr/lib/blas/libblas.so.3"),
            dict(kind="fft", N=2048, t_pair=0.04, blas=lib),
            dict(_snes(2048, 10, 0.05, 210.0, 10.5, 0.04, 3.6, lib), blas_lib=lib + "/libopenblas.so.0")]
    out = bench.summarise(recs)
    # the headline figures are the reference BLAS's
    assert out["time_per_pair_ratio"] == pytest.approx(1.5, rel=1e-12) and out["overhead_max"] == 3.5
    alt = out["blas"][lib]
    assert alt["loaded"] == [lib + "/libopenblas.so.0"]
    assert alt["time_per_pair_ratio"] == pytest.approx(10.5 / (210 * 0.04), rel=1e-12)
    (c,) = alt["cases"]
    assert c["seconds_ratio"] == pytest.approx(10.5 / 12.0, rel=1e-12)
    assert c["pairs_ratio"] == pytest.approx(1.05, rel=1e-12)
    assert c["tpp_ratio"] == pytest.approx((10.5 / 210) / (12.0 / 200), rel=1e-12)
    assert "BLAS /opt/openblas / reference: N=2048" in capsys.readouterr().out


def test_loaded_blas_names_petsc_blas(bench):
    """The worker's proof of which BLAS ran: once PETSc is loaded, its BLAS is among the mapped libraries."""
    from petsc4py import PETSc  # noqa: F401  (maps libpetsc and the libblas.so.3 it links)
    libs = bench._loaded_blas().split(",")
    assert any(os.path.basename(p).startswith(("libblas", "libopenblas")) for p in libs), libs


def test_profile_shares_classifies_py_spy_stacks(tmp_path):
    """benchmarks/profile_shares.py: each sample goes to one kind by its innermost Python frame and the
    native code below it; samples outside solve_contact (the farm's idle thread) are dropped."""
    import json
    import subprocess
    import sys
    top = "main (vecontact/cli.py:1);solve_contact (vecontact/solver/contact.py:140);"
    lines = [
        top + "SlabFFT.apply (vecontact/core/pfft.py:364);_run (vecontact/core/pfft.py:111);"
              "fftw_execute (libfftw3.so.3) 6",
        top + "SlabFFT._a2b (vecontact/core/pfft.py:220);PMPI_Alltoallw (libmpi.so.12) 2",
        top + "SlabFFT._b2a (vecontact/core/pfft.py:223);memcpy (libc.so.6) 1",
        top + "SlabFFT.apply (vecontact/core/pfft.py:364);multiply (numpy/_core/_multiarray_umath.so) 1",
        top + "ContactOperator.measures (vecontact/solver/operator.py:137);"
              "minimum (numpy/_core/_multiarray_umath.so) 3",
        top + "SingleGMRES._dots (vecontact/solver/single.py:84);"
              "sgemv_kernel_4x4 (libscipy_openblas64_-32a4b2a6.so) 1",
        top + "SlabFFT._allsum (vecontact/core/pfft.py:428);PMPI_Reduce (libmpi.so.12) 1",
        top + "ncp_solve (vecontact/solver/snes.py:251);VecMAXPY_Seq (libpetsc.so.3.26) 4",
        top + "ncp_solve (vecontact/solver/snes.py:251) 2",
        "Hub.loop (vecontact/farm/transport.py:149);clock_nanosleep (libc.so.6) 50",
    ]
    prof = tmp_path / "prof.txt"
    prof.write_text("\n".join(lines) + "\n")
    p = subprocess.run([sys.executable, os.path.join(ROOT, "benchmarks", "profile_shares.py"), str(prof)],
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 0, p.stderr
    out = json.loads(p.stdout.strip().splitlines()[-1])
    assert out["samples"] == 21
    want = dict(fftw=6, transposes=3, numpy=4, mpi=1, petsc=4, python=2, other=0)   # numpy's OpenBLAS: numpy
    want["pair rest"] = 1
    for k, n in want.items():
        assert out[k] == pytest.approx(n / 21, abs=1e-12), k
    assert out["in_pair"] == pytest.approx(10 / 21, abs=1e-12)


def test_the_matched_overhead_counts_only_oracles_that_met_the_solves_test(bench):
    """overhead_matched_max: against the oracle refined to the solve's accuracy, where it got there;
    overhead_max stays the plain oracle's (#15's target); the text names a refinement that fell short."""
    met = dict(_snes(1024, 10, 0.3, 500.0, 4.0, 0.005, 1.89, None), oracle_iterations=131, oracle_pairs=264.0,
               oracle_matched_iterations=228, oracle_matched_pairs=461.0, oracle_matched_converged=True,
               oracle_matched_measure=9.2e-9, oracle_measure=1.4e-4, overhead_matched=500.0 / 461.0)
    short = dict(met, N=2048, overhead=1.5, oracle_matched_converged=False, oracle_matched_measure=1e-7,
                 overhead_matched=0.5)
    plain = dict(_snes(512, 10, 0.05, 80.0, 1.0, 0.005, 1.7, None), oracle_matched_pairs=None,
                 oracle_matched_converged=None, overhead_matched=None)
    out = bench.summarise([met, short, plain])
    assert out["overhead_max"] == 1.89
    assert out["overhead_matched_max"] == pytest.approx(500.0 / 461.0, rel=1e-12)
    assert out["overhead_matched_cases"] == "1 of 3"
    assert "measure 1.0e-07 not met" in bench._oracle_text(short)
    assert "its measure 1.4e-04" in bench._oracle_text(met) and "overhead_matched=1.08" in bench._oracle_text(met)
