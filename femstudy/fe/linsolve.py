"""Sparse symmetric positive-definite solvers for A x = b, chosen by what is installed,
the problem size and the free memory.

Every method is set up once (factorisation or multigrid hierarchy) and then solves any
number of right-hand sides; the transient and modal analyses rely on that.

| method   | package                        | what it does                                           |
|----------|--------------------------------|--------------------------------------------------------|
| pardiso  | pypardiso (Intel MKL)          | sparse Cholesky (mtype 2) on the upper triangle         |
| cholmod  | scikit-sparse (SuiteSparse)    | supernodal sparse Cholesky                               |
| superlu  | scipy                          | LU, minimum-degree ordering on AᵀA+A, symmetric mode     |
| amg      | pyamg                          | smoothed aggregation (rigid-body near-null space) + CG |

``method="auto"`` takes PARDISO when it is importable and its own memory estimate (from the
symbolic analysis) fits in the available memory, then CHOLMOD, then SuperLU below
:data:`SUPERLU_MAX_DOFS`, and AMG-CG otherwise, or when PARDISO's estimate does not fit.
Timings behind these rules: docs/solver.md.
"""

from __future__ import annotations

import importlib.util
import logging
import os
import time
import warnings

import numpy as np
import scipy.sparse as sp

from femstudy.errors import UserError, require

log = logging.getLogger(__name__)

METHODS = ("pardiso", "cholmod", "superlu", "amg")
#: The pure-scipy fallback's switch from SuperLU to AMG-CG. On the femur SuperLU took 11 s
#: and 0.9 GiB at 45k DOFs, 105 s and 5 GiB at 154k (fill grows ~n^4/3), while AMG-CG took
#: 13 s and 24 s per solve: SuperLU is faster for any transient up to here (docs/solver.md).
SUPERLU_MAX_DOFS = 200_000
#: Fraction of the available memory a factorisation may plan to use.
MEMORY_FRACTION = 0.7


def _installed(name: str) -> bool:
    """Whether module ``name`` is installed, found without importing it (pyamg alone takes
    0.3 s to import, and only the chosen method's package is needed)."""
    try:
        return importlib.util.find_spec(name) is not None
    except ImportError:  # the parent package is missing
        return False


def available() -> list[str]:
    """The methods whose packages are installed here, in order of preference."""
    packages = {"pardiso": "pypardiso", "cholmod": "sksparse.cholmod", "superlu": "scipy.sparse.linalg",
                "amg": "pyamg"}
    return [m for m in METHODS if _installed(packages[m])]


def load_runtimes() -> None:
    """Load the runtime libraries of the installed direct solvers (MKL for PARDISO), so that a
    thread limit set now (threadpoolctl) reaches them too."""
    if "pardiso" in available():
        import pypardiso

        pypardiso.PyPardisoSolver()


def available_memory_bytes() -> int:
    import psutil
    return int(psutil.virtual_memory().available)


def rigid_body_modes(nodes: np.ndarray) -> np.ndarray:
    """The six rigid-body displacement fields (3 translations, 3 rotations ω × x) as columns
    of a (3 n_nodes, 6) array in the x, y, z-interleaved DOF order."""
    x = nodes - nodes.mean(axis=0)
    R = np.zeros((len(x), 3, 6))
    R[:, [0, 1, 2], [0, 1, 2]] = 1.0
    for k, axis in enumerate(np.eye(3)):
        R[:, :, 3 + k] = np.cross(axis, x)
    return R.reshape(-1, 6)


class Factor:
    """A solver for one SPD matrix: ``solve(b)`` for b of shape (n,) or (n, k)."""

    method = ""
    #: Factorisations made, and right-hand sides served without one (femstudy.fe.kept).
    factorisations, served = 1, 0

    def __init__(self, A: sp.spmatrix):
        self.n = A.shape[0]
        self.nnz = A.nnz
        self.setup_s = 0.0
        self.solves = 0
        self.solve_s = 0.0

    def solve(self, b: np.ndarray, x0: np.ndarray | None = None) -> np.ndarray:
        start = time.perf_counter()
        x = self._solve(np.asarray(b, dtype=float), x0)
        self.solve_s += time.perf_counter() - start
        self.solves += 1
        return x

    def close(self) -> None:
        """Release the factorisation where it lives outside Python (PARDISO: in MKL); the other
        methods' memory goes when the factor is dropped. A closed factor cannot solve."""

    def describe(self) -> str:
        per = f", {self.solve_s / self.solves:.3f} s per solve" if self.solves else ""
        return f"{self.method}: {self.n:,} unknowns, set-up {self.setup_s:.2f} s{per}"


class PardisoFactor(Factor):
    """MKL PARDISO Cholesky. The factor stays inside the MKL handle and every solve calls
    phase 33 (forward/backward substitution) directly, so pypardiso neither copies nor
    re-hashes A per solve."""

    method = "pardiso"

    def __init__(self, A, memory_limit_bytes: float | None = None):
        super().__init__(A)
        import pypardiso
        start = time.perf_counter()
        self.upper = sp.triu(A, format="csr")
        self.upper.sort_indices()
        self._pardiso = pypardiso.PyPardisoSolver(mtype=2)
        # pypardiso searches sys.prefix for MKL's runtime on every solver it makes (~0.3 s,
        # four times in a study with the hole); once found, later solvers take it from here
        os.environ.setdefault("PYPARDISO_MKL_RT", self._pardiso.libmkl._name)
        # iparm (1-based): 1 = use these settings, 2 = METIS nested dissection ordering, run in
        # parallel (3: the default femur's analysis phase 1.4–1.5 s against 2.0 s for serial
        # METIS, same factor size), 8 = no iterative refinement (with MKL's defaults every solve
        # ran two refinement steps, tripling its cost without improving the residual; Cholesky
        # has no pivots to fix)
        self._pardiso.set_iparm(1, 1)
        self._pardiso.set_iparm(2, 3)
        self._pardiso.set_iparm(8, 0)
        self._pardiso.set_iparm(10, 8)
        self._pardiso.set_phase(11)
        self._pardiso._call_pardiso(self.upper, np.zeros((self.n, 1)))
        self.planned_bytes = 1024 * int(max(self._pardiso.iparm[14], self._pardiso.iparm[15] + self._pardiso.iparm[16]))
        if memory_limit_bytes is not None and self.planned_bytes > memory_limit_bytes:
            self.close()
            raise MemoryError(f"PARDISO plans {self.planned_bytes / 2**30:.1f} GiB")
        self._pardiso.set_phase(22)
        self._pardiso._call_pardiso(self.upper, np.zeros((self.n, 1)))
        self.setup_s = time.perf_counter() - start

    def _solve(self, b, x0):
        self._pardiso.set_phase(33)
        return self._pardiso._call_pardiso(self.upper, np.asfortranarray(b))

    def close(self):
        """Release MKL's memory for this factorisation."""
        if getattr(self, "_pardiso", None) is not None:
            try:
                self._pardiso.free_memory(everything=True)
            except ImportError:  # interpreter shutting down; the process frees everything anyway
                pass
            self._pardiso = None

    def __del__(self):
        self.close()


class CholmodFactor(Factor):
    method = "cholmod"

    def __init__(self, A):
        super().__init__(A)
        from sksparse.cholmod import cholesky
        start = time.perf_counter()
        self._factor = cholesky(sp.csc_matrix(A))
        self.setup_s = time.perf_counter() - start

    def _solve(self, b, x0):
        return self._factor(b)


class SuperLUFactor(Factor):
    """scipy's SuperLU with the ordering that suits symmetric FE matrices (scipy's default
    COLAMD takes minutes and GBs on P2 elasticity; docs/solver.md)."""

    method = "superlu"

    def __init__(self, A):
        super().__init__(A)
        from scipy.sparse.linalg import splu
        start = time.perf_counter()
        self._lu = splu(sp.csc_matrix(A), permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                        options={"SymmetricMode": True})
        self.setup_s = time.perf_counter() - start

    def _solve(self, b, x0):
        return self._lu.solve(b)


class AMGFactor(Factor):
    """Smoothed-aggregation AMG preconditioned CG to relative residual ``rtol`` (1e-8: far
    below the model's own errors; each solve starts from ``x0``, the previous step's answer
    in a transient). The near-null space is the rigid-body modes restricted to the unknowns."""

    method = "amg"

    def __init__(self, A, near_null: np.ndarray | None, rtol: float = 1e-8, maxiter: int = 500):
        super().__init__(A)
        import pyamg
        start = time.perf_counter()
        self.A = sp.csr_matrix(A)
        self.rtol, self.maxiter = rtol, maxiter
        # with rigid-body modes the unknowns come as (x, y, z) per node: aggregate nodes, not DOFs
        blocked = near_null is not None and self.A.shape[0] % 3 == 0
        matrix = sp.bsr_matrix(self.A, blocksize=(3, 3)) if blocked else self.A
        # energy-minimising prolongation smoothing: half the CG iterations of the default
        # (43 against 82 on a 126k-DOF P2 femur, docs/solver.md) for 50 % more set-up
        self._ml = pyamg.smoothed_aggregation_solver(matrix, B=near_null, symmetry="symmetric", smooth="energy")
        self.setup_s = time.perf_counter() - start
        self.iterations = 0

    def _solve(self, b, x0):
        if b.ndim == 2:
            return np.column_stack([self._solve(col, None if x0 is None else x0[:, k])
                                    for k, col in enumerate(b.T)])
        residuals = []
        x = self._ml.solve(b, x0=x0, tol=self.rtol, maxiter=self.maxiter, accel="cg", residuals=residuals)
        self.iterations += len(residuals) - 1
        norm_b = np.linalg.norm(b)
        if norm_b > 0 and np.linalg.norm(b - self.A @ x) > 10 * self.rtol * norm_b:
            warnings.warn(f"AMG-CG stopped after {self.maxiter} iterations above rtol {self.rtol:g}",
                          RuntimeWarning, stacklevel=3)
        return x


def choose(n: int, methods: list[str] | None = None) -> list[str]:
    """Methods to try for n unknowns, best first (before the memory check)."""
    methods = available() if methods is None else methods
    order = [m for m in ("pardiso", "cholmod") if m in methods]
    if "superlu" in methods and n <= SUPERLU_MAX_DOFS:
        order.append("superlu")
    if "amg" in methods:
        order.append("amg")
    if "superlu" in methods and "superlu" not in order:
        order.append("superlu")
    return order


def factorize(A, method: str = "auto", near_null: np.ndarray | None = None) -> Factor:
    """Set up a solver for the SPD matrix A [any units]; logs the method that ran.

    method    : "auto" or one of :data:`METHODS`
    near_null : (n, 6) rigid-body modes for AMG (ignored by the direct methods)
    """
    require(method == "auto" or method in METHODS,
            f"unknown linear solver '{method}': choose auto or one of {', '.join(METHODS)}")
    A = sp.csr_matrix(A)
    installed = available()
    if method != "auto":
        require(method in installed, f"linear solver '{method}' is not installed here "
                                     f"(available: {', '.join(installed)})")
        candidates = [method]
    else:
        candidates = choose(A.shape[0], installed)
    limit = MEMORY_FRACTION * available_memory_bytes()
    for name in list(candidates):
        if name not in candidates:
            continue
        try:
            if name == "pardiso":
                factor = PardisoFactor(A, memory_limit_bytes=limit)
            elif name == "cholmod":
                factor = CholmodFactor(A)
            elif name == "superlu":
                factor = SuperLUFactor(A)
            else:
                factor = AMGFactor(A, near_null)
        except MemoryError as exc:
            if method != "auto":
                raise UserError(f"the {name} factorisation of {A.shape[0]:,} unknowns does not fit in memory "
                                f"({exc}, {limit / 2**30:.1f} GiB usable); use a coarser mesh or --solver amg") from None
            # the other direct methods fill in as much (CHOLMOD measured 10 % less, SuperLU more)
            # and have no estimate to check first: go to the iterative method
            candidates[:] = [m for m in candidates if m == "amg"]
            log.warning("%s does not fit in memory (%s); using AMG-CG", name, exc)
            continue
        log.info("linear solver %s", factor.describe())
        return factor
    raise UserError(f"no linear solver could handle {A.shape[0]:,} unknowns in "
                    f"{limit / 2**30:.1f} GiB of memory; use a coarser mesh")
