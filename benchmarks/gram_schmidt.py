"""Benchmark of the Gram-Schmidt update of the float32 GMRES (vecontact/solver/single.py).

Usage (from the repository root):
    python benchmarks/gram_schmidt.py [--n 6000000] [--basis 5,10,20] [--repeats 7]

After the products h = V^T t, classical Gram-Schmidt forms t -= h @ V and then |t|.  Done on whole
vectors that is a product u = h @ V, a subtraction and a norm: three passes over t and two over u.
``SingleGMRES._subtract`` does all three a block of ``single._BLOCK`` entries at a time, so t's block
and u's stay in cache.  Both run side by side on the same float32 data (n local entries, basis of k
vectors: a free set of 72 % of 4096^2 on 2 ranks is 6e6), fastest of --repeats; printed per k: the
milliseconds of each, their ratio, and the block sizes 2^15 ... 2^19 (the default is marked).

Then per k, one iteration's orthogonalisation as ``SingleGMRES.solve`` does it (the products ``_dots``
and the blocked update) against the same plus the pass that normalised the new vector into the next
basis row (t / |t| -> V[k]), which the unnormalised basis of session 39 no longer makes; the two
run in turn, fastest of 3 x --repeats each.
"""
import argparse
import os
import sys
import time

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from vecontact.solver import single  # noqa: E402
from vecontact.solver.single import SingleGMRES  # noqa: E402


def _fastest(f, repeats):
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        f()
        best = min(best, time.perf_counter() - t0)
    return best * 1e3


def _alternating(f, g, repeats):
    """The fastest of ``repeats`` runs of f and of g (ms), run in turn so that both see the same drift."""
    best = [float("inf"), float("inf")]
    for _ in range(repeats):
        for i, h in enumerate((f, g)):
            t0 = time.perf_counter()
            h()
            best[i] = min(best[i], time.perf_counter() - t0)
    return best[0] * 1e3, best[1] * 1e3


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=6_000_000)
    ap.add_argument("--basis", type=str, default="5,10,20")
    ap.add_argument("--repeats", type=int, default=7)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    default = single._BLOCK
    blocks = [1 << p for p in range(15, 20)]
    print(f"n = {args.n}, float32; ms per update (fastest of {args.repeats}); default block {default}")
    for k in (int(s) for s in args.basis.split(",")):
        V = rng.standard_normal((k, args.n)).astype(np.float32)
        h = (1e-3 * rng.standard_normal(k)).astype(np.float32)    # small: t stays the same size
        t = rng.standard_normal(args.n).astype(np.float32)
        gm = SingleGMRES(8, 2, lambda v: np.asarray(v, dtype=np.float64))
        u = np.empty_like(t)

        def whole():
            np.dot(h, V, out=u)
            np.subtract(t, u, out=t)
            gm._dots(t.reshape(1, -1), t)

        ref = _fastest(whole, args.repeats)
        row = []
        for b in blocks:
            single._BLOCK = b
            g = SingleGMRES(args.n, 2, gm.allsum)
            ms = _fastest(lambda: g._subtract(V, h, t), args.repeats)
            row.append(f"{b}{'*' if b == default else ''}: {ms:.1f} ({ms / ref:.2f}x)")
        single._BLOCK = default
        print(f"k = {k:3d}  whole vectors {ref:.1f}  blocks " + "  ".join(row), flush=True)
        g = SingleGMRES(args.n, 2, gm.allsum)
        dst = np.empty_like(t)

        def iteration():
            g._dots(V, t)
            g._subtract(V, h, t)

        def normalised():
            iteration()
            np.multiply(t, np.float32(0.5), out=dst)

        a, b = _alternating(iteration, normalised, 3 * args.repeats)
        print(f"        an iteration's orthogonalisation {a:.1f}; with the normalisation pass {b:.1f} "
              f"(unnormalised / normalised {a / b:.2f}x)", flush=True)


if __name__ == "__main__":
    main()
