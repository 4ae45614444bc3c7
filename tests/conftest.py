import os
import sys

import pyfftw
import pytest

from vecontact.solver import warmstart

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture(autouse=True)
def _fresh_fft_plans():
    """Each test plans its FFTs afresh, from FFTW's empty in-process wisdom: an estimate plan otherwise
    takes what earlier tests measured or loaded from the machine's wisdom file, and the coarse grids'
    SlabFFTs (warmstart's cache) keep the plans of the test that made them.  A test's rounding, and the
    path of a solve near a stall, would then depend on the test order, the machine's load and its cache
    (seen on an empty cache: test_solver_edge's coarse and fine grids took other paths)."""
    pyfftw.forget_wisdom()
    warmstart._FFT_CACHE.clear()
    yield
