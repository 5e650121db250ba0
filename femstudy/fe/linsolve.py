"""Sparse symmetric positive-definite solvers for A x = b, chosen by what is installed,
the problem size and the free memory.

Every method is set up once (factorisation or multigrid hierarchy) and then solves any
number of right-hand sides; the transient and modal analyses rely on that.

| method   | package                        | what it does                                           |
|----------|--------------------------------|--------------------------------------------------------|
| pardiso  | Intel MKL (femstudy.fe.pardiso) | sparse Cholesky (mtype 2), single precision + refinement |
| cholmod  | scikit-sparse (SuiteSparse)    | supernodal sparse Cholesky                               |
| superlu  | scipy                          | LU, minimum-degree ordering on AᵀA+A, symmetric mode     |
| amg      | pyamg                          | smoothed aggregation (rigid-body near-null space) + CG |

``method="auto"`` takes PARDISO when it is importable and its own memory estimate (from the
symbolic analysis) fits in the available memory, then CHOLMOD, then SuperLU below
:data:`SUPERLU_MAX_DOFS`, and AMG-CG otherwise, or when PARDISO's estimate does not fit.
Timings behind these rules: docs/solver.md.
"""

from __future__ import annotations

import functools
import importlib.util
import logging
import time
import warnings

import numpy as np
import scipy.sparse as sp

from femstudy.errors import UserError, require
from femstudy.fe import pardiso, sparse_products

log = logging.getLogger(__name__)

METHODS = ("pardiso", "cholmod", "superlu", "amg")
#: The pure-scipy fallback's switch from SuperLU to AMG-CG. On the femur SuperLU took 11 s
#: and 0.9 GiB at 45k DOFs, 105 s and 5 GiB at 154k (fill grows ~n^4/3), while AMG-CG took
#: 13 s and 24 s per solve: SuperLU is faster for any transient up to here (docs/solver.md).
SUPERLU_MAX_DOFS = 200_000
#: Fraction of the available memory a factorisation may plan to use.
MEMORY_FRACTION = 0.7
#: A single-precision factor's refinement stops when the estimated remaining error (the last
#: correction times its contraction rate) is below this fraction of the solution: the forward
#: error of a double-precision direct solve here (PARDISO and MUMPS agree to 1e-12–7e-12).
REFINE_RTOL = 1e-12
#: Corrections smaller than this (relative to x) that no longer shrink are round-off: done.
REFINE_FLOOR = 1e-9
PRECISIONS = ("single", "double")
#: Most refinement steps before the matrix is factorised again in double precision.
MAX_REFINEMENTS = 15


def _installed(name: str) -> bool:
    """Whether module ``name`` is installed, found without importing it (pyamg alone takes
    0.3 s to import, and only the chosen method's package is needed); ``"mkl"`` is MKL's
    runtime library, which PARDISO is part of."""
    if name == "mkl":
        from femstudy.fe.pardiso import runtime_path
        return runtime_path() is not None
    try:
        return importlib.util.find_spec(name) is not None
    except ImportError:  # the parent package is missing
        return False


def available() -> list[str]:
    """The methods whose packages are installed here, in order of preference."""
    packages = {"pardiso": "mkl", "cholmod": "sksparse.cholmod", "superlu": "scipy.sparse.linalg",
                "amg": "pyamg"}
    return [m for m in METHODS if _installed(packages[m])]


def load_runtimes() -> None:
    """Load the runtime libraries of the installed direct solvers (MKL for PARDISO), so that a
    thread limit set now (threadpoolctl) reaches them too."""
    if "pardiso" in available():
        pardiso.load()


def one_openblas_thread():
    """A context in which OpenBLAS (numpy's dense products) runs on one thread, for work that
    alternates dense products with PARDISO substitutions. OpenBLAS's idle threads spin for a
    while after each call, and on two cores a substitution that follows ran at half speed (16 mm
    femur, four columns: 48 ms after a pause, 92–101 ms right after a dense product; 55 ms with
    OpenBLAS on one thread). The dense work between substitutions is products of tall, thin
    blocks, which one thread does as fast (0.34 M × 20 by its transpose: 3.4 against 3.3 ms)."""
    return _openblas_pools().limit(limits=1)


@functools.cache
def _openblas_pools():
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController().select(internal_api="openblas")


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
        x = self._timed(self._solve, np.asarray(b, dtype=float), x0)
        self.solves += 1
        return x

    def _timed(self, work, *args):
        """work(*args), its wall time added to :attr:`solve_s` [s]."""
        start = time.perf_counter()
        out = work(*args)
        self.solve_s += time.perf_counter() - start
        return out

    #: Whether :meth:`approximate` is less accurate than :meth:`solve` (one substitution of a
    #: single-precision factor, which :meth:`solve` refines).
    refines = False

    def approximate(self, b: np.ndarray) -> np.ndarray:
        """x ≈ A⁻¹b at the cost of one substitution: :meth:`solve` itself, unless
        :attr:`refines` (then ~1e-2 relative error on the femur, docs/solver.md)."""
        return self.solve(b)

    def close(self) -> None:
        """Release the factorisation where it lives outside Python (PARDISO: in MKL); the other
        methods' memory goes when the factor is dropped. A closed factor cannot solve."""

    def describe(self) -> str:
        per = f", {self.solve_s / self.solves:.3f} s per solve" if self.solves else ""
        return f"{self.method}: {self.n:,} unknowns, set-up {self.setup_s:.2f} s{per}"


def free_block(A: sp.csr_matrix | sp.bsr_matrix, free: np.ndarray, upper: bool = False,
               dtype=None) -> sp.csr_matrix | sp.bsr_matrix:
    """A[free][:, free] of a CSR matrix with sorted indices, in one pass over its entries (the
    rows and columns keep their order, so the result's indices stay sorted and K_ff and M_ff,
    restricted from one pattern, share theirs). Of a BSR matrix, ``free`` numbers block rows
    (nodes) and whole blocks are kept: a ninth of the index work, and no conversion.
    ``upper``: only the upper triangle (of entries, or of blocks with the diagonal blocks
    whole); ``dtype``: the values' type (default A's)."""
    size = A.blocksize[0] if A.format == "bsr" else 1
    n = A.shape[0] // size
    number = np.full(n, -1, dtype=A.indices.dtype)
    number[free] = np.arange(len(free), dtype=A.indices.dtype)
    rows = np.repeat(number, np.diff(A.indptr))
    columns = number[A.indices]
    # a column at or right of a kept row (≥ 0) is itself kept
    keep = (rows >= 0) & (columns >= rows if upper else columns >= 0)
    del rows
    kept = np.concatenate([[0], np.cumsum(keep, dtype=np.int64)])
    indptr = np.concatenate([[0], np.cumsum(kept[A.indptr[free + 1]] - kept[A.indptr[free]])])
    shape = (size * len(free), size * len(free))
    data = A.data[keep] if dtype is None else A.data[keep].astype(dtype)
    restricted = type(A)((data, columns[keep], indptr), shape=shape)
    restricted.has_sorted_indices = A.has_sorted_indices
    return restricted


def upper_triangle(A: sp.csr_matrix, dtype=np.float64) -> sp.csr_matrix:
    """The upper triangle (diagonal included) of a CSR matrix with sorted indices, its values
    as ``dtype``: one pass over the entries (scipy's ``triu`` goes through COO, 4× slower)."""
    return free_block(A, np.arange(A.shape[0]), upper=True, dtype=dtype)


def upper_blocks(A: sp.csr_matrix | sp.bsr_matrix, size: int, dtype=np.float64) -> sp.bsr_matrix:
    """The upper triangle of ``size``² blocks (diagonal blocks whole) of a CSR matrix, or of a
    BSR matrix of such blocks (no conversion then), as BSR with values ``dtype``."""
    B = A if A.format == "bsr" and A.blocksize == (size, size) else sp.bsr_matrix(A, blocksize=(size, size))
    B.sort_indices()
    return free_block(B, np.arange(B.shape[0] // size), upper=True, dtype=dtype)


def compressed(A) -> sp.csr_matrix | sp.bsr_matrix:
    """A sparse matrix as CSR, or as it is when it is CSR or BSR already (no copy)."""
    return A if sp.issparse(A) and A.format in ("csr", "bsr") else sp.csr_matrix(A)


def padded(x: np.ndarray, positions: np.ndarray, n: int) -> np.ndarray:
    """x (len(positions),) or (len(positions), k) placed at ``positions`` of n rows, zero elsewhere."""
    full = np.zeros((n,) + x.shape[1:])
    full[positions] = x
    return full


def restricted_product(A, positions: np.ndarray, X: np.ndarray) -> np.ndarray:
    """A[positions][:, positions] @ X without forming that block: A times X padded with zeros
    (:func:`femstudy.fe.sparse_products.times`: MKL's product of all columns at once)."""
    return sparse_products.times(A, padded(X, positions, A.shape[0]))[positions]


class Restriction:
    """K_ff = K[free][:, free] for a K of 3×3 node blocks (BSR, sorted) and clamps holding whole
    nodes, *not formed*: PARDISO's upper blocks come from K in one pass, and K_ff x is K times x
    padded with zeros on the clamped nodes. A static solve needs no more; forming K_ff's copy
    and first-touching its memory (70 MB at 16 mm) took 0.16 s of a 2.5 s process.

    ``matrix()`` forms it (BSR) for the solvers that need the entries, once; ``formed`` is it,
    or None while it has not been formed."""

    has_sorted_indices = True

    def __init__(self, K: sp.bsr_matrix, nodes: np.ndarray):
        if K.format != "bsr" or K.blocksize != (3, 3):
            raise ValueError("a Restriction takes K as BSR of 3×3 node blocks")
        self.full = K if K.has_sorted_indices else K.sorted_indices()
        self.formed: sp.bsr_matrix | None = None
        self.nodes = np.asarray(nodes)
        self.dofs = (3 * self.nodes[:, None] + np.arange(3)).ravel()
        self.shape = (len(self.dofs), len(self.dofs))
        self.dtype = K.dtype

    @property
    def nnz(self) -> int:
        """K's stored entries (an upper bound on K_ff's)."""
        return self.full.nnz

    def __matmul__(self, X: np.ndarray) -> np.ndarray:
        return restricted_product(self.full, self.dofs, X)

    def matrix(self) -> sp.bsr_matrix:
        if self.formed is None:
            self.formed = free_block(self.full, self.nodes)
        return self.formed

    def upper(self, dtype) -> sp.bsr_matrix:
        return free_block(self.full, self.nodes, upper=True, dtype=dtype)


#: Block size of the matrices PARDISO is given: a node's 3 displacements. A matrix whose 3×3
#: blocks would hold more than :data:`BLOCK_FILL` explicit zeros per entry goes as CSR.
BLOCK = 3
BLOCK_FILL = 0.05


def pardiso_upper(A: sp.csr_matrix | sp.bsr_matrix, dtype) -> sp.csr_matrix | sp.bsr_matrix:
    """A's upper triangle for PARDISO: of 3×3 blocks when A is made of them (PARDISO then orders
    and analyses the node graph, 9× smaller: 0.7 s against 1.9 s of CPU on the 8 mm femur, and a
    third less memory planned), else of entries. A BSR matrix of 3×3 blocks (the assembly's
    K_ff) is taken as it is, and a :class:`Restriction`'s blocks are taken from K."""
    if isinstance(A, Restriction):
        return A.upper(dtype)
    if A.format == "bsr" and A.blocksize == (BLOCK, BLOCK):
        return upper_blocks(A, BLOCK, dtype)
    A = A.tocsr()
    if A.shape[0] % BLOCK == 0:
        upper = upper_blocks(A, BLOCK, dtype)
        # entries of A in the upper blocks: the strict upper triangle twice plus the diagonal blocks
        if upper.data.size <= (1 + BLOCK_FILL) * (A.nnz + 3 * A.shape[0]) / 2:
            return upper
    return upper_triangle(A, dtype)


class PardisoFactor(Factor):
    """MKL PARDISO Cholesky (mtype 2) of the upper triangle, factorised in single precision
    and refined to double precision at every solve (mixed-precision iterative refinement).

    The single-precision factor takes half the memory and about half the time of the double
    one (it streams half the bytes); each solve then runs conjugate gradients preconditioned
    by it, with residuals in double precision, until the estimated remaining error is below
    :data:`REFINE_RTOL` of x — the accuracy of a double-precision direct solve, reached in 5–6
    single-precision substitutions on the femur (7–10 by plain refinement x ← x + L⁻ᵀL⁻¹(b − A x),
    which contracts the error 30- to 100-fold a step; docs/solver.md). Should
    the refinement ever stall (a matrix too ill-conditioned for single precision), the matrix is
    factorised again in double precision and solved directly. ``precision="double"`` (the
    default) factorises in double precision: one substitution per solve, the cheaper choice
    for the many solves of a transient, a modal analysis or a study.

    ``timings``: PARDISO's input (upper triangle of 3×3 blocks), analysis (ordering, symbolic
    factorisation) and numeric factorisation [s].
    """

    method = "pardiso"

    def __init__(self, A, memory_limit_bytes: float | None = None, precision: str = "double"):
        super().__init__(A)
        start = time.perf_counter()
        self.A = A if A.has_sorted_indices else A.sorted_indices()
        self.refinements = 0
        self._handle = None
        self._make(np.float32 if precision == "single" else np.float64, memory_limit_bytes)
        self.setup_s = time.perf_counter() - start

    def _make(self, dtype, memory_limit_bytes: float | None) -> None:
        self.close()
        # iparm (1-based): 2 = 3: METIS nested dissection ordering run in parallel (the default
        # femur's analysis 1.4–1.5 s against 2.0 s serial, same factor); 8 = 0: no iterative
        # refinement inside PARDISO (done here, with a double-precision residual); 10 = 8:
        # pivot perturbation 1e-8 (none occur in Cholesky of an SPD matrix)
        start = time.perf_counter()
        handle = pardiso.SymmetricPositiveDefinite(pardiso_upper(self.A, dtype), {2: 3, 8: 0, 10: 8})
        self._handle = handle
        analysis = time.perf_counter()
        self.planned_bytes = handle.analyse()
        if memory_limit_bytes is not None and self.planned_bytes > memory_limit_bytes:
            self.close()
            raise MemoryError(f"PARDISO plans {self.planned_bytes / 2**30:.1f} GiB")
        numeric = time.perf_counter()
        handle.factorize()
        self.timings = {"input_s": analysis - start, "analysis_s": numeric - analysis,
                        "factor_s": time.perf_counter() - numeric}
        self.precision = "single" if dtype == np.float32 else "double"

    @property
    def refines(self) -> bool:
        return self.precision == "single"

    def approximate(self, b):
        return self._timed(self._substitute, np.asarray(b, dtype=float))

    def _solve(self, b, x0):
        return self._refined(b, self._substitute(b), REFINE_RTOL)

    def _substitute(self, b):
        """L̃⁻ᵀL̃⁻¹b, in double precision: one substitution with the factor.

        PARDISO runs a substitution of two or three columns in one thread, while it spreads
        one column, or four and more, over its threads (16 mm femur, 2 threads: 20, 48, 54 and
        42 ms for 1, 2, 3 and 4 columns; 5 mm: 99, 245, 269, 201 ms; one thread: 43, 51, 59,
        68 ms). With more than one thread, two columns therefore go one at a time and three
        as four (a zero column added)."""
        columns = 1 if b.ndim == 1 else b.shape[1]
        if columns in (2, 3) and pardiso.max_threads() > 1:
            if columns == 2:
                return np.column_stack([self._handle.solve(b[:, j]) for j in range(2)]).astype(float)
            return self._handle.solve(np.column_stack([b, np.zeros(len(b))]))[:, :3].astype(float)
        return self._handle.solve(b).astype(float)

    def _refined(self, b, x, rtol):
        """Conjugate gradients on A from x = L̃⁻ᵀL̃⁻¹b (one substitution's answer), preconditioned
        by the single-precision factor; iterates and residuals in double precision. Each
        preconditioned residual z = L̃⁻ᵀL̃⁻¹r is a refinement correction: ‖z‖/‖x‖ estimates x's
        error, and the first of them (the error of one substitution) its contraction ρ. Stops
        when ‖z‖/‖x‖ · ρ (the error of x + z) is below ``rtol``, and returns x + z."""
        if self.precision == "double":
            return x
        B, X = b.reshape(self.n, -1), x.reshape(self.n, -1)
        R = B - self.A @ X
        Z = self._substitute(R)
        contraction, previous, P, rz_old = None, np.inf, None, None
        for _ in range(MAX_REFINEMENTS):
            self.refinements += 1
            scale = np.abs(X).max(axis=0)
            size = float(np.max(np.abs(Z).max(axis=0) / np.where(scale > 0, scale, 1.0)))
            contraction = min(size, 1.0) if contraction is None else contraction
            stalled = size > 0.5 * previous
            if size * contraction <= rtol or (stalled and size <= REFINE_FLOOR):
                X += Z
                return x  # X is a view of x
            if stalled:
                break
            previous = size
            rz = np.einsum("ij,ij->j", R, Z)
            P = Z if P is None else Z + P * _ratio(rz, rz_old)
            AP = self.A @ P
            alpha = _ratio(rz, np.einsum("ij,ij->j", P, AP))
            X += P * alpha
            R -= AP * alpha
            rz_old = rz
            Z = self._substitute(R)
        log.warning("single-precision refinement stalled (correction %.1e of x); factorising in double precision",
                    size)
        self._make(np.float64, None)
        return self._substitute(b)

    def describe(self) -> str:
        return super().describe() + (f", {self.precision} precision" if self._handle is not None else "")

    def close(self):
        """Release MKL's memory for this factorisation."""
        handle, self._handle = getattr(self, "_handle", None), None
        if handle is not None:
            try:
                handle.release()
            except ImportError:  # interpreter shutting down; the process frees everything anyway
                pass

    def __del__(self):
        self.close()


def _ratio(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a / b column by column, 0 where b is 0 (a column already solved exactly)."""
    return np.divide(a, b, out=np.zeros_like(a), where=b != 0)


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


def factorize(A, method: str = "auto", near_null: np.ndarray | None = None, precision: str = "double") -> Factor:
    """Set up a solver for the SPD matrix A [any units] (a sparse matrix, or a
    :class:`Restriction`); logs the method that ran.

    method    : "auto" or one of :data:`METHODS`
    near_null : (n, 6) rigid-body modes for AMG (ignored by the direct methods)
    precision : PARDISO's factorisation: "double" (one substitution per solve), or "single"
                (half the memory and time, each solve refined to double precision in 5–6
                substitutions: the faster choice for a few solves, e.g. a static analysis)
    """
    require(precision in PRECISIONS, f"unknown precision '{precision}': choose {' or '.join(PRECISIONS)}")
    require(method == "auto" or method in METHODS,
            f"unknown linear solver '{method}': choose auto or one of {', '.join(METHODS)}")
    # PARDISO takes the assembly's 3×3 blocks as they are, or a Restriction of them; the other
    # methods convert them
    A = A if isinstance(A, Restriction) else compressed(A)
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
            entries = A.matrix() if isinstance(A, Restriction) and name != "pardiso" else A
            if name == "pardiso":
                factor = PardisoFactor(A, memory_limit_bytes=limit, precision=precision)
            elif name == "cholmod":
                factor = CholmodFactor(entries)
            elif name == "superlu":
                factor = SuperLUFactor(entries)
            else:
                factor = AMGFactor(entries, near_null)
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
