"""The FFTW that pyfftw runs on: ./run builds FFTW with AVX2 codelets on x86-64 (README "Install")."""
import os

import pytest

from vecontact.core.pfft import default_wisdom_file, fftw_version


def test_fftw_version_is_read_from_the_library():
    v = fftw_version()
    assert v.startswith("fftw-3."), v


@pytest.mark.skipif(os.environ.get("VECONTACT_FFTW_MODE") != "source",
                    reason="not in an environment ./run built with FFTW from source")
def test_run_built_fftw_with_avx2():
    v = fftw_version()
    assert v.startswith("fftw-3.3.10") and "-avx2" in v, v


def test_wisdom_file_is_per_fftw_build(monkeypatch):
    import vecontact.core.pfft as pfft
    a = default_wisdom_file()
    monkeypatch.setattr(pfft, "fftw_version", lambda: "fftw-0.0-other")
    assert default_wisdom_file() != a
