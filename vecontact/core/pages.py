"""numpy's huge-page advice for the arrays allocated in a block of code.

On Linux numpy asks the kernel for transparent huge pages (madvise MADV_HUGEPAGE) on every array of at
least 4 MiB, unless NUMPY_MADVISE_HUGEPAGE=0.  That suits arrays that live long (the FFT's work buffers:
fewer TLB misses in the transposes), not blocks allocated and freed again and again, whose pages fault
in anew each time, 2 MiB a fault (benchmarks/RESULTS.md, "Huge pages").
"""
from __future__ import annotations

import contextlib

import numpy as np

__all__ = ["huge_page_advice"]


@contextlib.contextmanager
def huge_page_advice(enabled):
    """numpy's madvise(MADV_HUGEPAGE) on (``enabled`` True) or off for the arrays allocated inside the
    block; the previous choice is back after it."""
    advise = np._core.multiarray._set_madvise_hugepage
    before = advise(bool(enabled))
    try:
        yield
    finally:
        advise(before)
