"""Small dense systems for the Krylov solvers' tests (single.py, carry.py) and SingleGMRES's operands of them."""
import numpy as np


def allsum(values):
    """The global sum of one process: a float64 copy."""
    return np.asarray(values, dtype=np.float64).copy()


def system(n=240, seed=3, scale=1.0):
    """(A, B, b): a non-symmetric operator with a spread spectrum (GMRES needs tens of iterations) times
    ``scale``, an approximate inverse (of A / scale) as preconditioner, like the steps' stiffness /
    compliance pair, and a right-hand side."""
    rng = np.random.default_rng(seed)
    Q, _ = np.linalg.qr(rng.standard_normal((n, n)))
    lam = np.logspace(0, 2, n)
    A = scale * ((Q * lam) @ Q.T + 3.0 * rng.standard_normal((n, n)) / np.sqrt(n))
    B = np.linalg.inv((Q * lam) @ Q.T + 0.3 * np.eye(n) * lam.mean())
    b = rng.standard_normal(n)
    return A, B, b


def operators(A, B):
    """SingleGMRES's (u, out) callables of the dense matrices A and B (out in its own dtype)."""
    def apply(M):
        return lambda u, out: np.copyto(out, M @ u, casting="same_kind")
    return apply(A), apply(B)
