"""The ``vecontact`` command line: run, surface, plot, report, status, info, test.

Bad input gives one line ``vecontact: error: KEY: PROBLEM`` on stderr and exit status 2,
without a traceback and without writing anything.
"""
import argparse
import os
import sys
import warnings

from vecontact import __version__
from vecontact.errors import InputError, InputWarning


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        raise InputError("arguments", message)


def _parser():
    p = _Parser(prog="vecontact", description="Viscoelastic rough contact: Persson theory and exact solver")
    p.add_argument("--version", action="version", version=f"vecontact {__version__}")
    sub = p.add_subparsers(dest="command")
    r = sub.add_parser("run", help="run a job (theory, and numerics if enabled)")
    r.add_argument("job", help="YAML job file")
    r.add_argument("--quiet", action="store_true", help="no per-case progress lines")
    r.add_argument("-o", "--output", help="override the job's output file")
    r.add_argument("--no-plot", action="store_true", help="do not draw the figures at the end")
    r.add_argument("--q1", help="solve only the cases at these q1 (1/m, comma list) in this run; the "
                                "others stay to solve in the results file (a later run does them)")
    s = sub.add_parser("surface", help="write the job's generated surfaces without solving")
    s.add_argument("job")
    s.add_argument("-o", "--output", required=True, help="HDF5 file for the surfaces")
    pl = sub.add_parser("plot", help="draw the paper's figures from a results file")
    pl.add_argument("results", help="results HDF5 file")
    pl.add_argument("-o", "--outdir", help="folder for the PNGs (default: next to the results)")
    pl.add_argument("--maps", help="results file with contact fields (jobs/paper-maps.yaml) for Fig. 3")
    rp = sub.add_parser("report", help="the report's numbers from a results file, as markdown tables")
    rp.add_argument("results", help="results HDF5 file")
    rp.add_argument("--maps", help="results file with contact fields (jobs/paper-maps.yaml)")
    rp.add_argument("-o", "--output", help="markdown file (default: RESULTS without .h5 + -numbers.md)")
    st = sub.add_parser("status", help="how far a sweep has got and what failed, from its results file")
    st.add_argument("results", help="results HDF5 file")
    sub.add_parser("info", help="versions of the stack and the number of ranks")
    t = sub.add_parser("test", help="run the test suite (serial part; ./run test adds the MPI part)")
    t.add_argument("pytest_args", nargs=argparse.REMAINDER)
    return p


def _split_petsc(argv):
    """Arguments after the job that look like PETSc options (-snes_type newtonls ...)."""
    from vecontact.solver.options import split_argv
    return split_argv(argv, {"--quiet", "--no-plot", "-o", "--output", "--q1", "-h", "--help", "--version"})


def _info():
    from mpi4py import MPI
    import numpy
    import pyfftw
    import h5py
    from vecontact.core.pfft import fftw_version
    lines = [f"vecontact {__version__}", f"python {sys.version.split()[0]}", f"numpy {numpy.__version__}",
             f"mpi4py {__import__('mpi4py').__version__}",
             f"MPI library: {MPI.Get_library_version().splitlines()[0].strip()}",
             f"h5py {h5py.__version__} (HDF5 {h5py.version.hdf5_version})",
             f"pyfftw {pyfftw.__version__} (FFTW {fftw_version()})"]
    try:
        from petsc4py import PETSc
        v = PETSc.Sys.getVersion()
        lines.append(f"petsc4py {__import__('petsc4py').__version__}, PETSc {'.'.join(map(str, v))}")
    except ImportError as exc:
        lines.append(f"PETSc: not importable ({exc})")
    lines.append(f"ranks: {MPI.COMM_WORLD.size}")
    if MPI.COMM_WORLD.rank == 0:
        print("\n".join(lines))
    return 0


def _dispatch(argv):
    known, petsc = _split_petsc(argv)
    args = _parser().parse_args(known)
    if args.command == "info":
        return _info()
    if args.command == "test":
        import pytest
        root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        return pytest.main([os.path.join(root, "tests"), "--ignore", os.path.join(root, "tests", "mpi")]
                           + args.pytest_args)
    if args.command == "status":
        from vecontact.status import status
        return status(args.results)
    if args.command == "plot":
        from vecontact.plot import MAPS_SKIPPED, plot_results
        for path in plot_results(args.results, args.outdir, args.maps):
            print(path)
        if args.maps is None:
            print(f"vecontact: {MAPS_SKIPPED}")
        return 0
    if args.command == "report":
        from vecontact.analysis.report import write_report
        print(write_report(args.results, args.maps, args.output))
        return 0
    if args.command in ("run", "surface"):
        from mpi4py import MPI
        from vecontact import job as jobs
        job = jobs.load(args.job, output=getattr(args, "output", None) if args.command == "run" else None)
        if args.command == "surface":
            from vecontact.io.surfaces import write_job_surfaces
            write_job_surfaces(job, args.output, MPI.COMM_WORLD)
            return 0
        from vecontact.runner import run
        run(job, MPI.COMM_WORLD, quiet=args.quiet, petsc_args=petsc, only_q1=args.q1)
        if MPI.COMM_WORLD.rank == 0 and not args.no_plot:
            from vecontact.plot import plot_results
            paths = plot_results(job.output)
            if not args.quiet:
                print(f"vecontact: figures in {os.path.dirname(paths[0])}")
        return 0
    _parser().print_help()
    return 2


def _warning_line(message, category, filename, lineno, line=None, _default=warnings.formatwarning):
    """InputWarning as one line, like the errors; any other warning as Python prints it."""
    if issubclass(category, InputWarning):
        return f"vecontact: warning: {message}\n"
    return _default(message, category, filename, lineno, line)


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    warnings.formatwarning = _warning_line
    try:
        rc = _dispatch(argv)
        sys.stdout.flush()
        return rc
    except InputError as exc:
        if _rank() == 0:
            print(f"vecontact: error: {exc}", file=sys.stderr, flush=True)
        return 2
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        # reader gone (``vecontact status F | head``): no traceback; stdout must not flush at exit
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 141


def _rank():
    if "mpi4py.MPI" in sys.modules:
        return sys.modules["mpi4py.MPI"].COMM_WORLD.rank
    return 0
