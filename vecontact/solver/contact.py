"""``solve_contact``: the entry point of the exact numerical solver (see package docstring)."""
from __future__ import annotations

import contextlib
import functools
import time
from dataclasses import replace

import numpy as np
from threadpoolctl import threadpool_limits

from vecontact.core.pages import huge_page_advice
from vecontact.solver.operator import ContactOperator, is_elastic_on_grid
from vecontact.solver.options import parse, solver_items
from vecontact.solver.pk import pk_solve
from vecontact.solver.result import ContactResult, pair_weight, postprocess
from vecontact.solver.settings import SolverSettings
from vecontact.solver.warmstart import (bearing_guess, coarse_fft, coarse_levels, fourier_transfer,
                                        prolong_gap, smooth_gap, transfer_real)

__all__ = ["solve_contact"]

_METHODS = ("snes", "pk")
_STORE = ("pressure", "gap", "displacement")


def _check_warm(warm, fft):
    st = getattr(warm, "warm_state", None)
    if st is None:
        raise ValueError("warm: not a ContactResult of solve_contact (no warm-start state)")
    if st["N"] != fft.N or st["shape"] != tuple(fft.local_real_shape) or st["row_start"] != fft.row_start:
        raise ValueError(f"warm: result is for grid N={st['N']} rows {st['row_start']}.. "
                         f"shape {st['shape']}, this solve has N={fft.N} rows {fft.row_start}.. "
                         f"shape {fft.local_real_shape}")
    return st


def _solve_environment(solve):
    """Run ``solve`` with one BLAS thread and, unless its settings' huge_pages is "on", without numpy's
    huge-page advice (core/pages.py), then give both back.  The settings are resolved here, once
    (``settings`` with the ``-vc_`` entries of ``petsc_options``): ``solve`` gets them, and PETSc's
    entries alone as its ``petsc_options``.  Under mpiexec numpy's OpenBLAS otherwise starts a thread
    per core in every rank, and a 2-rank 1024^2 solve took 4.5x as long (RESULTS.md, "BLAS threads").
    A solve allocates and frees its Krylov bases and step scratch again and again; with 2 MiB pages
    each new block faults in anew: 4 KiB pages took 0.69-0.96x the seconds of the benchmark's cases,
    grid by grid (RESULTS.md, "Huge pages")."""
    @functools.wraps(solve)
    def in_environment(*args, settings=None, petsc_options=None, **kwargs):
        options, ours = solver_items(parse(petsc_options))
        cfg = (settings or SolverSettings()).with_options(ours)
        pages = huge_page_advice(False) if cfg.huge_pages == "off" else contextlib.nullcontext()
        with threadpool_limits(limits=1, user_api="blas"), pages:
            return solve(*args, settings=cfg, petsc_options=options, **kwargs)
    return in_environment


@_solve_environment
def solve_contact(fft, L, h, modulus, velocity, sigma0, *, tolerance=1e-8, method="snes",
                  petsc_options=None, warm=None, coarse=True, max_iterations=None,
                  store=("pressure", "gap", "displacement"), monitor=None, settings=None):
    """Steady sliding contact of a viscoelastic half-space on the rigid rough surface ``h``.

    Parameters
    ----------
    fft : SlabFFT of the N x N grid; L : period (m); h : local rows of the surface heights (m)
    modulus : callable E(omega) with attributes nu, E0, Einf; velocity : sliding speed (m/s, >= 0)
    sigma0 : nominal pressure (Pa, > 0)
    tolerance : scale-free convergence tolerance (complementarity / sigma0, penetration / h_rms,
        force balance); see operator.py
    method : "snes" (PETSc semismooth Newton, any modulus) or "pk" (Polonsky-Keer CG, elastic only:
        ValueError if Im E(q_x v) != 0 anywhere on the grid)
    petsc_options : dict or list of "-key value" strings (options.py): PETSc's options for the SNES/KSP
        (solver prefix added) and ``-vc_<field>`` overrides of ``settings``
    warm : previous ContactResult on the same grid and decomposition (previous load or velocity of a
        sweep).  snes: its gap, restricted to the coarsest grid, replaces the cold start there (with
        coarse=False the fine grid restarts from it directly); pk: its pressure (rescaled to the new
        sigma0) starts the CG.
    coarse : snes only; solve on the coarse grids N/2^k >= settings.coarse_min_n (at most
        settings.coarse_levels of them, coarsest first), each warm-starting the next by trigonometric
        interpolation + settings.smooth_sweeps projected Richardson sweeps (see warmstart.py); the coarse
        grids hold all the roughness of null-band surfaces.  Ignored when N is too small.
    max_iterations : Newton iterations (snes, fine grid; default settings.newton_max_it, and
        settings.fallback_max_it for the fallback's attempt) or CG iterations (pk, default
        settings.pk_max_it)
    store : which local fields to return ("pressure", "gap", "displacement"); without "displacement" its
        backward transform is skipped (mu needs only its spectrum: half an FFT pair less)
    monitor : optional callable(level_N, iteration, residual) for progress output
    settings : SolverSettings (settings.py; default: its defaults), every tuning constant of the solve

    Returns a ContactResult; never raises for non-convergence (converged=False, residual, reason).
    The BLAS runs one thread during the solve, whatever the environment asks for, and numpy does not
    ask for huge pages for the arrays the solve allocates unless settings.huge_pages is "on".
    """
    t0 = time.perf_counter()
    comm = fft.comm
    if method not in _METHODS:
        raise ValueError(f"method must be one of {_METHODS}, got {method!r}")
    store = tuple(store or ())
    for s in store:
        if s not in _STORE:
            raise ValueError(f"store: unknown field {s!r} (allowed {_STORE})")
    if not (tolerance > 0):
        raise ValueError("tolerance must be > 0")
    velocity = float(velocity)
    options, cfg = petsc_options, settings      # PETSc's entries and the settings: _solve_environment's
    if method == "pk" and not is_elastic_on_grid(fft, L, modulus, velocity, rtol=cfg.elastic_rtol):
        raise ValueError("method 'pk' (Polonsky-Keer) needs an elastic operator: Im E(q_x v) != 0 on "
                         "this grid at this velocity; use method 'snes'")
    wst = _check_warm(warm, fft) if warm is not None else None

    tr0 = fft.transforms
    op = ContactOperator(fft, L, modulus, velocity, sigma0, h)
    levels_info = []
    by_level = {}

    coarse_start = {}   # coarse SlabFFT -> its transform counter when first used in this call

    def touch(f):
        coarse_start.setdefault(f.N, (f, f.transforms))

    if method == "pk":
        p0 = None
        if wst is not None and wst.get("pressure") is not None:
            p0 = wst["pressure"]
        maxit = cfg.pk_max_it if max_iterations is None else int(max_iterations)
        mon = None if monitor is None else (lambda it, r: monitor(fft.N, it, r))
        phat, ghat, info = pk_solve(op, tol=tolerance, max_iter=maxit, p0=p0, monitor=mon)
        act = phat > 0
        info["linear_iterations"] = 0
    else:
        from vecontact.solver.snes import ncp_solve
        g0 = None
        direct = False          # a coarse grid needed the fallback: the finer ones start with it
        lv = coarse_levels(fft.N, comm.size, min_n=cfg.coarse_min_n, max_levels=cfg.coarse_levels) if coarse else []
        if wst is not None and not lv:
            g0 = wst["gap"] / op.ell
        elif lv:
            prev = None
            # the coarse grids' steps unsmoothed: smoothing them changed the pairs by -3 .. +4 % (RESULTS.md).
            # No retry after edge_newton_max iterations there, nor the finest grid's stall rule: a coarse
            # solve ends at coarse_max_it anyway, and the study's coarse grids creep to their tolerance for
            # up to 49 iterations (RESULTS.md).  One that ends unconverged, far from its tolerance, takes
            # the fallback (fallback_coarse), to coarse_max_it too: the study's have ended at measures up
            # to 0.17.  Its full steps hand over sooner where they wander far from it (coarse_stall)
            coarse_cfg = replace(cfg, step_sweeps=0, edge_newton_max=0, fallback_stall=0,
                                 fallback_max_it=cfg.coarse_max_it,
                                 fallback=cfg.fallback if cfg.fallback_coarse == "on" else "none")
            for n in lv:
                fc = coarse_fft(fft, n)
                touch(fc)
                Hc = fourier_transfer(fft, op.h_fourier, fc)
                hc = fc.backward(Hc)
                opc = ContactOperator(fc, L, modulus, velocity, sigma0, hc, h_fourier=Hc)
                if prev is None and wst is not None:
                    # previous solution of the sweep, restricted to the coarsest grid
                    gw = transfer_real(fft, wst["gap"], fc)
                    gc0 = smooth_gap(opc, np.maximum(gw / opc.ell, 0.0), cfg.smooth_sweeps, cfg.smooth_ratio)
                elif prev is None:
                    gc0 = bearing_guess(opc, cfg.bearing_area_min, cfg.bearing_area_max, cfg.bearing_tol)
                else:
                    gc0 = smooth_gap(opc, prolong_gap(prev[0], prev[1], prev[2], opc), cfg.smooth_sweeps,
                                     cfg.smooth_ratio)
                mon = None if monitor is None else (lambda it, r, m, n=n: monitor(n, it, r))
                # coarse_stall from coarse_stall_min_n up: on 64^2 it saved little, and its handover sent
                # easy solves' finer grids to the fallback at up to 2x their pairs (RESULTS.md)
                gh, ph, _, inf = ncp_solve(opc, gc0, max(cfg.coarse_tol, tolerance), cfg.coarse_max_it,
                                           coarse_cfg if n >= cfg.coarse_stall_min_n else
                                           replace(coarse_cfg, coarse_stall=0), options, monitor=mon,
                                           direct=direct, fallback_above=cfg.fallback_coarse_measure)
                levels_info.append(_level_info(n, inf))
                # full steps that could not solve a coarse grid wandered on the finer ones too: the finest
                # grid took 1.4-24x the pairs of the fallback's attempt alone (RESULTS.md, "fallback_coarse")
                direct = direct or "fallback_retry" in inf
                if inf.get("edge_retry"):
                    # the term stalled this grid's steps: the finer grids go without it, so that a stall
                    # costs one stalled attempt, not one on every grid (RESULTS.md, "Stalls caught early")
                    coarse_cfg = replace(coarse_cfg, edge_window=0)
                    cfg = replace(cfg, edge_window=0)
                prev = (opc, gh, ph)
            if prev is not None:
                g0 = prolong_gap(prev[0], prev[1], prev[2], op)
                g0 = smooth_gap(op, g0, cfg.smooth_sweeps, cfg.smooth_ratio)
            # the coarse levels' operators and fields are not needed by the fine solve: free them first
            # (at 4096^2 the N/2 level's alone is about 20 bytes a fine grid point)
            prev = opc = Hc = hc = gc0 = gh = ph = gw = None
            for f, _ in coarse_start.values():
                f.release_arrays()
        if g0 is None:
            g0 = bearing_guess(op, cfg.bearing_area_min, cfg.bearing_area_max, cfg.bearing_tol)
        maxit = cfg.newton_max_it if max_iterations is None else int(max_iterations)
        if max_iterations is not None:      # the caller's cap is every attempt's, the fallback's too
            cfg = replace(cfg, fallback_max_it=maxit)
        mon = None if monitor is None else (lambda it, r, m: monitor(fft.N, it, r))
        ghat, phat, act, info = ncp_solve(op, g0, tolerance, maxit, cfg, options, monitor=mon, direct=direct)
        levels_info.append(_level_info(fft.N, info))

    # returned fields (SI): zero pressure off contact, zero gap in contact
    p_out = np.where(act, phat * op.sigma0, 0.0)
    g_out = np.where(act, 0.0, ghat * op.ell)
    scal, w = postprocess(op, p_out, g_out, displacement="displacement" in store)
    fft.release_arrays()            # the plans would keep the last fields of this solve alive
    for n, (f, t0c) in coarse_start.items():
        by_level[n] = (f.transforms - t0c) / 2.0
    by_level[fft.N] = (fft.transforms - tr0) / 2.0
    pairs = sum(v * pair_weight(n, fft.N) for n, v in by_level.items())
    seconds = comm.bcast(time.perf_counter() - t0, root=0)
    info_meas = info["measures"]
    res = ContactResult(
        area=scal["area"], mu=scal["mu"], mu_geometric=scal["mu_geometric"], mean_gap=scal["mean_gap"],
        rigid_position=scal["rigid_position"], converged=bool(info["converged"]),
        iterations=int(info["iterations"]), linear_iterations=int(info.get("linear_iterations", 0)),
        fft_pairs=float(pairs), residual=float(info["residual"]), seconds=float(seconds),
        reason=str(info["reason"]), method=method,
        pressure=p_out if "pressure" in store else None,
        gap=g_out if "gap" in store else None,
        displacement=w if "displacement" in store else None,
        fft_pairs_by_level={int(k): float(v) for k, v in sorted(by_level.items())},
        measures=dict(complementarity=info_meas[0], penetration=info_meas[1], force=info_meas[2]),
        sigma0=float(sigma0), velocity=velocity, N=fft.N, L=float(L),
        diagnostics=dict(levels=levels_info, ell=op.ell, hrms=op.hrms, k=op.k, kappa=op.kappa,
                         history=[(int(a), float(b)) for a, b, *_ in info.get("history", [])],
                         active_set_changes=info.get("nchg", []),
                         linear_history=info.get("lin_history", []),
                         step_modes=info.get("modes", []),
                         measure_checks=info.get("measure_checks", []),
                         single_iterations=int(info.get("single_iterations", 0)),
                         float32_pairs=bool(info.get("float32_pairs", False)),
                         mixed_pairs=int(info.get("mixed_pairs", 0)),
                         carried_directions=int(info.get("carried_directions", 0)),
                         stalls=int(info.get("stalls", 0)),
                         smoothed_steps=int(info.get("smoothed_steps", 0)),
                         **_attempts(info)),
        # warm-start state: the gap always (snes restarts from it), the pressure when it is stored
        # anyway or for "pk" (which restarts from it); set res.warm_state = None to free the memory
        warm_state=dict(N=fft.N, shape=tuple(fft.local_real_shape), row_start=fft.row_start,
                        gap=g_out, pressure=p_out if (method == "pk" or "pressure" in store) else None,
                        sigma0=float(sigma0), velocity=velocity),
    )
    return res


def _level_info(n, info):
    """One grid level's entry of diagnostics["levels"], from its ncp_solve info; its ``history`` is the
    measure after each Newton iteration of its last attempt (from the start's): a rule for the coarse
    grids can then be checked on a study's stored paths, as the finest grid's are (RESULTS.md)."""
    return dict(N=n, **{k: info.get(k) for k in ("iterations", "linear_iterations", "converged", "residual",
                                                 "reason")},
                **_attempts(info), history=[float(m) for _, m, *_ in info.get("history", [])])


def _attempts(info):
    """The earlier attempts of an ncp_solve (null where there was none) and whether it started with the
    fallback's: the same keys in the result's diagnostics and in each of its levels."""
    return dict({k: info.get(k) for k in ("edge_retry", "fallback_retry", "direct_retry", "vi_retry")},
                fallback_direct=bool(info.get("fallback_direct", False)))
