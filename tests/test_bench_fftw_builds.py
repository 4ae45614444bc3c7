"""benchmarks/fftw_builds.py: two FFTW libraries side by side in one process (here the one pyfftw runs on,
twice: the same build must give the same round trip)."""
import os
import re

import numpy as np
import pytest

from reference.bench import load


def _bench():
    return load("fftw_builds")


def _loaded_fftw(single):
    """Path of the libfftw3 (or libfftw3f) this process mapped for pyfftw."""
    import pyfftw  # noqa: F401  (maps the library)
    if not os.path.exists("/proc/self/maps"):
        pytest.skip("needs /proc/self/maps")
    name = r"libfftw3f[-.]" if single else r"libfftw3[-.]"
    with open("/proc/self/maps") as fh:
        paths = {ln.split()[-1] for ln in fh if ln.rstrip().endswith(".so") or ".so." in ln}
    hits = sorted(p for p in paths if re.search(name, os.path.basename(p)))
    if not hits:
        pytest.skip("pyfftw's FFTW not found in the process maps")
    return hits[0]


@pytest.mark.parametrize("single", [False, True])
def test_same_build_twice_round_trips_and_times(single):
    from vecontact.core.pfft import fftw_version
    lib = _loaded_fftw(single)
    r = _bench().compare(lib, lib, N=32, rounds=2, per_round=2, planner="estimate", single=single)
    assert r["version_a"] == r["version_b"] and r["version_a"].startswith("fftw-3.")
    if not single:
        assert r["version_a"] == fftw_version()      # the library pyfftw runs on
    eps = np.finfo(np.float32 if single else np.float64).eps
    # one pair's round trip of unit-variance data: a few eps x log2(N^2)
    assert r["error_a"] < 50 * eps and r["error_b"] < 50 * eps
    assert r["error_a"] == r["error_b"]               # same library, same plan flags, same data
    assert r["min_a"] > 0 and r["min_b"] > 0 and r["ratio_median"] > 0
