"""Mesh-convergence assessment: observed order, Richardson extrapolation and the Grid
Convergence Index (Roache; the procedure of Celik et al. 2008, J Fluids Eng 130:078001,
adopted by ASME V&V 20).

For three solutions φ1, φ2, φ3 on meshes of representative size h1 < h2 < h3 with ratios
r21 = h2/h1 and r32 = h3/h2 (need not be equal):

    ε21 = φ2 − φ1,  ε32 = φ3 − φ2,  s = sign(ε32/ε21)
    p   = |ln|ε32/ε21| + ln((r21^p − s)/(r32^p − s))| / ln r21       (solved by iteration)
    φ_ext = (r21^p φ1 − φ2)/(r21^p − 1)
    GCI_fine = F_s |(φ1 − φ2)/φ1| / (r21^p − 1),  F_s = 1.25 for three meshes

The representative size of an unstructured mesh is h = (V/N)^(1/3) (V the volume, N the
number of cells). Verdicts follow the ratio R = ε21/ε32: a model φ0 + c h^p with p > 0
exists only for 0 < R < ln r21 / ln r32 (= 1 for a constant ratio), which is monotone
convergence; R < 0 is oscillatory; R at or above the bound is divergence. A quantity that grows without bound under
refinement — the stress at the edge of a load patch, which is singular in the continuum —
diverges, or converges at an order far below the element's; both are reported as "not
converging" with the reason.

Below a resolution floor the changes carry no order: each TetWild mesh approximates the
surface anew (the volume moves by tenths of a percent between sizes), so once the three
finest values agree within ``RESOLUTION`` (0.5 %) the quantity is reported as converged,
with that spread as its uncertainty, rather than as diverging on sub-percent noise.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

SAFETY_FACTOR = 1.25
RESOLUTION = 0.005


@dataclass(frozen=True)
class Assessment:
    """Convergence of one quantity from the three finest meshes."""

    quantity: str
    h: tuple[float, float, float]
    values: tuple[float, float, float]
    ratio_R: float
    observed_order: float | None
    extrapolated: float | None
    gci_fine: float | None
    verdict: str
    reason: str

    def as_dict(self) -> dict:
        return asdict(self)


def observed_order(phi, h, max_iter: int = 200, tol: float = 1e-12) -> float | None:
    """Apparent order p from three solutions (fine to coarse), or None if undefined."""
    (f1, f2, f3), (h1, h2, h3) = phi, h
    e21, e32 = f2 - f1, f3 - f2
    if e21 == 0 or e32 == 0:
        return None
    r21, r32 = h2 / h1, h3 / h2
    s = math.copysign(1.0, e32 / e21)
    p = abs(math.log(abs(e32 / e21))) / math.log(r21)
    for _ in range(max_iter):
        q_arg = (r21 ** p - s) / (r32 ** p - s)
        if q_arg <= 0:
            return None
        new = abs(math.log(abs(e32 / e21)) + math.log(q_arg)) / math.log(r21)
        if abs(new - p) < tol:
            return new
        p = new
    return p


def assess(quantity: str, h, values, expected_order: float, singular_hint: bool = False) -> Assessment:
    """Assess convergence of ``values`` (same order as ``h``; the three finest are used).

    ``expected_order`` is the formal order of the quantity (e.g. 2 for P1 displacements,
    3 for P2); an observed order below a quarter of it (half, for a quantity marked singular)
    is not trusted as convergence.
    ``singular_hint`` marks quantities expected to be singular (peak stress at a patch edge).
    """
    order = np.argsort(h)[:3]
    hh = tuple(float(h[i]) for i in order)
    vv = tuple(float(values[i]) for i in order)
    f1, f2, f3 = vv
    e21, e32 = f2 - f1, f3 - f2
    R = e21 / e32 if e32 != 0 else math.inf
    bound = math.log(hh[1] / hh[0]) / math.log(hh[2] / hh[1])
    p = observed_order(vv, hh)
    base = dict(quantity=quantity, h=hh, values=vv, ratio_R=R, observed_order=p)
    spread = (max(vv) - min(vv)) / abs(f1) if f1 != 0 else (0.0 if max(vv) == min(vv) else math.inf)
    if spread <= RESOLUTION:
        return Assessment(**base, extrapolated=f1, gci_fine=spread, verdict="converged",
                          reason=f"the three finest values agree within {100 * spread:.2f} % (resolution "
                                 f"{100 * RESOLUTION:g} %: the remeshed geometry itself varies that much); "
                                 "GCI column: that spread")
    if R >= bound or R < 0:
        kind = "diverging" if R >= bound else "oscillating"
        reason = (f"{kind} (R = {R:.3g} >= {bound:.3g}): the change does not shrink under refinement"
                  if R >= bound else f"{kind} (R = {R:.3g}): the change alternates in sign")
        if singular_hint and R >= bound:
            reason += "; a peak stress at the load-patch edge is singular in the continuum and grows as h → 0"
        return Assessment(**base, extrapolated=None, gci_fine=None, verdict="not converging", reason=reason)
    if p is None:
        return Assessment(**base, extrapolated=None, gci_fine=None, verdict="not converging",
                          reason="no observed order: the two finest values are equal but the coarser one differs")
    r21 = hh[1] / hh[0]
    extrapolated = (r21 ** p * f1 - f2) / (r21 ** p - 1)
    gci = SAFETY_FACTOR * abs((f1 - f2) / f1) / (r21 ** p - 1) if f1 != 0 else None
    if p < (0.5 if singular_hint else 0.25) * expected_order:
        reason = (f"observed order {p:.2f} is far below the formal {expected_order:g}"
                  + ("; consistent with a singular peak stress at the load-patch edge" if singular_hint else ""))
        return Assessment(**base, extrapolated=extrapolated, gci_fine=gci, verdict="not converging", reason=reason)
    return Assessment(**base, extrapolated=extrapolated, gci_fine=gci, verdict="converging",
                      reason=f"monotone (R = {R:.3g} < {bound:.3g}), observed order {p:.2f} "
                             f"(formal {expected_order:g})")


def coarsest_meeting_target(h, values, reference: float, target: float):
    """Largest h whose value is within ``target`` (relative) of ``reference``, with its error;
    finer meshes must all meet the target too (the error must stay below it)."""
    pairs = sorted(zip(h, values))  # fine to coarse
    if reference == 0:
        return None
    best = None
    for size, value in pairs:
        error = abs(value - reference) / abs(reference)
        if error > target:
            break
        best = (size, error)
    return best
