"""Where a solve's time goes, from a py-spy profile: shares of the samples by kind of work.

Usage:
    py-spy record --native -r 20 -d 150 -f raw -o prof.txt -p PID      (one rank of a running solve)
    python benchmarks/profile_shares.py prof.txt [--inside solve_contact]

Reads py-spy's "raw" (collapsed stack) output, keeps the samples whose stack contains ``--inside``
(default ``solve_contact``: the solver, not the farm's idle coordinator thread) and classifies each by
the innermost Python frame and the native libraries below it:

  fftw        FFTW (the row and column transforms of SlabFFT)
  transposes  anything under SlabFFT._a2b / _b2a (the Alltoallw transposes, their memory copies)
  pair rest   other native code under the pair's own frames (SlabFFT.apply, apply_across, _pair,
              _forward_into, _backward_from_B, pfft._run): the multiply, the 1/N^2 scaling, memory copies
  numpy       numpy elsewhere (restriction to the contact set, measures, residual), its own OpenBLAS
              included (libscipy_openblas: the float32 Gram-Schmidt of single.py, whose samples
              show the BLAS kernel right under the Python frame)
  mpi         MPI elsewhere (fft.sum reductions, allreduce)
  petsc       PETSc native code (Krylov vector work, SNES) and the BLAS it links
  python      the interpreter itself
  other       the rest

Prints one line per kind (share of the kept samples) and, as the last line, a JSON object with the
shares and ``in_pair`` = fftw + transposes + pair rest.
"""
import argparse
import collections
import json
import re

KINDS = ("fftw", "transposes", "pair rest", "numpy", "mpi", "petsc", "python", "other")
# the pair's own frames, by name and file (a bare "_run" could be any module's)
_PAIR_FRAME = re.compile(r"(SlabFFT\.(apply|apply_across|_pair|_forward_into|_backward_from_B)|_run)"
                         r" \(.*core/pfft\.py:")


def classify(frames):
    """Kind of one sample; ``frames`` outermost first, as py-spy writes them."""
    native = []
    python = None
    for f in reversed(frames):
        if ".py:" in f:
            python = f
            break
        native.append(f)
    libs = " ".join(native)
    if python is not None and re.match(r"SlabFFT\._(a2b|b2a) ", python):
        return "transposes"
    if re.search(r"fftw", libs, re.I):
        return "fftw"
    if native and python is not None and _PAIR_FRAME.match(python):
        return "pair rest"
    if re.search(r"multiarray|umath|numpy|scipy_openblas", libs, re.I):
        return "numpy"
    if re.search(r"libmpi|mpich|libuc[pst]|fabric", libs, re.I):
        return "mpi"
    if re.search(r"petsc|blas", libs, re.I):
        return "petsc"
    if not native:
        return "python"
    return "other"


def shares(lines, inside="solve_contact"):
    """{kind: share} over the samples of ``lines`` (py-spy raw format) whose stack contains ``inside``;
    also returns the number of samples kept."""
    count = collections.Counter()
    for line in lines:
        line = line.rstrip()
        if not line or inside not in line:
            continue
        stack, n = line.rsplit(" ", 1)
        count[classify(stack.split(";"))] += int(n)
    total = sum(count.values())
    return {k: (count[k] / total if total else 0.0) for k in KINDS}, total


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("profile", help="py-spy raw output (-f raw)")
    ap.add_argument("--inside", default="solve_contact", help="keep samples whose stack contains this")
    args = ap.parse_args()
    with open(args.profile) as fh:
        sh, total = shares(fh, args.inside)
    print(f"samples {total}")
    for k in KINDS:
        print(f"{100 * sh[k]:6.1f} %  {k}")
    in_pair = sh["fftw"] + sh["transposes"] + sh["pair rest"]
    print(json.dumps(dict(samples=total, in_pair=in_pair, **sh)))


if __name__ == "__main__":
    main()
