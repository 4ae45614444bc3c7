"""Driver for benchmarks/peers.py: runs Tamaas and ContactMechanics INSIDE the peers' environment.

Never imported by vecontact and never run with the project's interpreter: ``benchmarks/peers.py``
starts it as ``PEERS_PYTHON benchmarks/peers_driver.py`` and talks to it through JSON lines, one
command per line on stdin, one answer per line on stdout (prefixed ``RESULT ``):

  {"cmd": "probe"}                                  versions, FFT backends, thread counts
  {"cmd": "load", "surface": PATH, "L": L, "E": E, "nu": nu}
                                                    read the N x N heights (m, .npy), build the
                                                    Tamaas model and the ContactMechanics substrate
  {"cmd": "pair", "repeats": R}                     median/min seconds of each peer's raw FFT pair
  {"cmd": "solve", "code": "tamaas"|"cm", "sigma0": S, "tol": T, "maxiter": M}
                                                    one cold-started load-controlled solve
  {"cmd": "quit"}

``--commands FILE`` reads the commands from FILE instead of stdin.

How each peer is driven (see benchmarks/PEERS.md):

* Tamaas 2.9, ``PolonskyKeerRey(model, h, tol)`` on a ``basic_2d`` model (E, nu given, so E* = E/(1-nu^2)
  is Tamaas's own), pressure primal and pressure constraint: ``solve(sigma0)`` imposes the MEAN
  pressure, i.e. load control.  Tolerance: Tamaas's own relative complementarity error.  The solver
  starts from the model's traction field, so the traction is zeroed before every solve (cold start).
  Iterations: parsed from Tamaas's own log line at convergence (iteration index n, 0-based: n + 1
  iterations).  FFT pairs: 2 per iteration (gradient K p and the critical step K t) + 1 (final
  gradient), measured by counting fftw_execute_dft_r2c/c2r calls under gdb (``--count-check``).
* ContactMechanics 1.8, ``constrained_conjugate_gradients(PeriodicFFTElasticHalfSpace, Topography,
  external_force=sigma0 L^2, ...)``: load control is native (the offset is re-derived every iteration).
  One tolerance t drives its three criteria: pentol = t h_rms (m), forcetol = t sigma0 dx^2 (pixel
  force, N), thermotol = t (relative).  FFT pairs: counted by wrapping the substrate's
  evaluate_disp/evaluate_force (one FFT pair each); cross-checked against the solver's own nfev
  (= 1 + 2 per iteration).

Contact area: fraction of points with p > 0.  Mean gap: g = u - h shifted so that its mean over the
contact points is 0, set to 0 on them, averaged over the grid (the same as vecontact's <g>).
"""
import json
import os
import re
import sys
import tempfile
import time

for _v in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_v, "1")

import numpy as np  # noqa: E402


def _threads():
    try:
        return len(os.listdir("/proc/self/task"))
    except OSError:
        return None


def _median(xs):
    xs = sorted(xs)
    n = len(xs)
    return xs[n // 2] if n % 2 else 0.5 * (xs[n // 2 - 1] + xs[n // 2])


class _StderrCapture:
    """Capture what C++ code writes to file descriptor 2 (Tamaas's logger) into a string."""

    def __enter__(self):
        sys.stderr.flush()
        self._tmp = tempfile.TemporaryFile(mode="w+b")
        self._saved = os.dup(2)
        os.dup2(self._tmp.fileno(), 2)
        return self

    def __exit__(self, *exc):
        sys.stderr.flush()
        os.dup2(self._saved, 2)
        os.close(self._saved)
        self._tmp.seek(0)
        self.text = self._tmp.read().decode("utf-8", "replace")
        self._tmp.close()
        return False


def _scalars(p, u, h):
    """A/A0 and mean gap (see module docstring) from pressure p, surface displacement u, heights h."""
    c = p > 0
    nc = int(np.count_nonzero(c))
    g = u - h
    if nc:
        g = g - g[c].mean()
    g = np.where(c, 0.0, g)
    return dict(area=nc / p.size, mean_gap=float(g.mean()), mean_pressure=float(p.mean()),
                min_gap_free=float(g[~c].min()) if nc < p.size else 0.0)


class Peers:
    def __init__(self):
        self.h = None

    # ------------------------------------------------------------------ set-up
    def probe(self):
        out = dict(threads_start=_threads())
        try:
            import tamaas as tm
            out["tamaas"] = tm.__version__
            info = tm.TamaasInfo
            out["tamaas_info"] = dict(backend=str(info.backend), has_mpi=bool(info.has_mpi),
                                      build_type=str(info.build_type))
        except Exception as e:  # noqa: BLE001 - reported, not fatal
            out["tamaas_error"] = f"{type(e).__name__}: {e}"
        try:
            import ContactMechanics
            import muGrid
            import SurfaceTopography
            out["cm"] = ContactMechanics.__version__
            out["surfacetopography"] = SurfaceTopography.__version__
            out["mugrid"] = getattr(muGrid, "__version__", "?")
        except Exception as e:  # noqa: BLE001
            out["cm_error"] = f"{type(e).__name__}: {e}"
        out["numpy"] = np.__version__
        out["python"] = sys.version.split()[0]
        return out

    def load(self, surface, L, E, nu):
        h = np.ascontiguousarray(np.load(surface), dtype=np.float64)
        if h.ndim != 2 or h.shape[0] != h.shape[1]:
            raise ValueError(f"surface {surface}: expected an N x N array, got {h.shape}")
        self.h = h
        self.N = N = h.shape[0]
        self.L = float(L)
        self.E = float(E)
        self.nu = float(nu)
        self.Estar = self.E / (1.0 - self.nu ** 2)
        self.hrms = float(np.sqrt(np.mean((h - h.mean()) ** 2)))
        out = dict(N=N, hrms=self.hrms)
        t = time.perf_counter()
        import tamaas as tm
        tm.set_log_level(tm.LogLevel.info)
        self.tm = tm
        self.model = tm.ModelFactory.createModel(tm.model_type.basic_2d, [self.L, self.L], [N, N])
        self.model.E = self.E
        self.model.nu = self.nu
        out["tamaas_Estar"] = float(self.model.E_star)
        # build the Westergaard operator once (its FFT plans), outside the timed solves
        self.model.traction[...] = 0.0
        tm.PolonskyKeerRey(self.model, self.h, 1e-6)
        out["tamaas_setup_s"] = time.perf_counter() - t

        t = time.perf_counter()
        from ContactMechanics import PeriodicFFTElasticHalfSpace
        from SurfaceTopography import Topography
        # poisson left at 0: 'young' is then the contact modulus E* (ContactMechanics' convention)
        self.sub = PeriodicFFTElasticHalfSpace((N, N), self.Estar, physical_sizes=(self.L, self.L))
        self.topo = Topography(self.h, physical_sizes=(self.L, self.L), periodic=True)
        out["cm_contact_modulus"] = float(self.sub.contact_modulus)
        out["cm_setup_s"] = time.perf_counter() - t
        out["threads"] = _threads()
        return out

    # ------------------------------------------------------------------ raw FFT pairs
    def pair(self, repeats=9):
        N = self.N
        rng = np.random.default_rng(0)
        out = {}
        op = self.model.operators["Westergaard::neumann"]
        p = rng.random((N, N, 1))
        u = np.zeros((N, N, 1))
        op(p, u)
        ts = []
        for _ in range(repeats):
            t = time.perf_counter()
            op(p, u)
            ts.append(time.perf_counter() - t)
        out["tamaas"] = dict(median=_median(ts), min=min(ts))
        f = rng.random((N, N))
        self.sub.evaluate_disp(f)
        ts = []
        for _ in range(repeats):
            t = time.perf_counter()
            self.sub.evaluate_disp(f)
            ts.append(time.perf_counter() - t)
        out["cm"] = dict(median=_median(ts), min=min(ts))
        out["threads"] = _threads()
        return out

    # ------------------------------------------------------------------ solves
    def solve(self, code, sigma0, tol, maxiter=100000):
        if code == "tamaas":
            return self._tamaas(sigma0, tol, maxiter)
        if code == "cm":
            return self._cm(sigma0, tol, maxiter)
        raise ValueError(f"unknown code {code!r}")

    def _tamaas(self, sigma0, tol, maxiter):
        tm = self.tm
        model = self.model
        model.traction[...] = 0.0          # PolonskyKeerRey starts from the model's traction
        model.displacement[...] = 0.0
        with _StderrCapture() as cap:
            t = time.perf_counter()
            solver = tm.PolonskyKeerRey(model, self.h, float(tol))
            solver.setMaxIterations(int(maxiter))
            solver.setDumpFrequency(1 << 30)   # only the first and the final log lines
            err = solver.solve(float(sigma0))
            seconds = time.perf_counter() - t
        rows = [int(m.group(1)) for m in re.finditer(r"^\s*(\d+)\s+\S+\s+\S+\s*$", cap.text, re.M)]
        if not rows:
            raise RuntimeError("Tamaas: no iteration line in its log:\n" + cap.text[-2000:])
        iterations = rows[-1] + 1            # the log shows the 0-based index of the last iteration
        p = np.array(model.traction, copy=True).reshape(self.N, self.N)
        u = np.array(model.displacement, copy=True).reshape(self.N, self.N)
        out = dict(code="tamaas", tol=tol, sigma0=sigma0, seconds=seconds, iterations=iterations,
                   pairs=2 * iterations + 1, error=float(err),
                   converged=bool(err <= tol and iterations < maxiter), threads=_threads())
        out.update(_scalars(p, u, self.h))
        return out

    def _cm(self, sigma0, tol, maxiter):
        from ContactMechanics.Optimization import constrained_conjugate_gradients as ccg
        sub = self.sub
        count = [0]
        cls = type(sub)

        def disp(forces, _f=cls.evaluate_disp):
            count[0] += 1
            return _f(sub, forces)

        def force(d, _f=cls.evaluate_force):
            count[0] += 1
            return _f(sub, d)

        sub.evaluate_disp = disp
        sub.evaluate_force = force
        dx2 = (self.L / self.N) ** 2
        try:
            t = time.perf_counter()
            res = ccg(sub, self.topo, external_force=float(sigma0) * self.L ** 2,
                      pentol=float(tol) * self.hrms, forcetol=float(tol) * float(sigma0) * dx2,
                      thermotol=float(tol), maxiter=int(maxiter))
            seconds = time.perf_counter() - t
        finally:
            del sub.evaluate_disp
            del sub.evaluate_force
        if count[0] != res.nfev:
            raise RuntimeError(f"ContactMechanics: counted {count[0]} FFT pairs, its nfev says {res.nfev}")
        p = np.asarray(res.jac).reshape(self.N, self.N) / dx2
        u = np.asarray(res.x).reshape(self.N, self.N)
        out = dict(code="cm", tol=tol, sigma0=sigma0, seconds=seconds, iterations=int(res.nit),
                   pairs=int(count[0]), nfev=int(res.nfev), converged=bool(res.success),
                   message=str(res.message), threads=_threads())
        out.update(_scalars(p, u, self.h))
        return out


def main():
    peers = Peers()
    out = sys.stdout
    # keep the protocol channel clean: anything the libraries print goes to stderr
    sys.stdout = sys.stderr
    # commands from stdin, or from the file after --commands (used under gdb by --count-check)
    src = open(sys.argv[2]) if len(sys.argv) > 2 and sys.argv[1] == "--commands" else sys.stdin
    for line in src:
        line = line.strip()
        if not line:
            continue
        cmd = json.loads(line)
        name = cmd.pop("cmd")
        if name == "quit":
            break
        try:
            res = getattr(peers, name)(**cmd)
            ans = dict(ok=True, result=res)
        except Exception as e:  # noqa: BLE001 - reported to the caller, which fails loudly
            import traceback
            ans = dict(ok=False, error=f"{type(e).__name__}: {e}", traceback=traceback.format_exc())
        out.write("RESULT " + json.dumps(ans) + "\n")
        out.flush()


if __name__ == "__main__":
    main()
