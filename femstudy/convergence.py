"""Mesh-convergence assessment: observed order, Richardson extrapolation and the Grid
Convergence Index (Roache; the procedure of Celik et al. 2008, J Fluids Eng 130:078001,
adopted by ASME V&V 20; the order cap and safety factors of Oberkampf & Roy 2010, §8.7).

For three solutions φ1, φ2, φ3 on meshes of representative size h1 < h2 < h3 with ratios
r21 = h2/h1 and r32 = h3/h2 (need not be equal):

    ε21 = φ2 − φ1,  ε32 = φ3 − φ2,  s = sign(ε32/ε21)
    p   = |ln|ε32/ε21| + ln((r21^p − s)/(r32^p − s))| / ln r21       (solved by iteration)
    φ_ext = (r21^p̂ φ1 − φ2)/(r21^p̂ − 1),  GCI_fine = F_s |(φ1 − φ2)/φ1| / (r21^p̂ − 1)

with p̂ = min(max(p, 0.5), formal order): an observed order above the formal one is not
trusted (the asymptotic range is not reached, or errors cancel) and is capped, and the safety
factor is F_s = 1.25 when p lies within 10 % of the formal order, 3 otherwise.

The mesh measure h is the quantity's own: (V/N)^(1/3) of the whole mesh for global
quantities (deflection), the element size where the quantity lives for local ones (the drill
site's, for stresses near the hole).

Verdicts, in order:

- "singular": a quantity singular in the continuum (the peak stress at a load edge or a
  re-entrant corner) is never called converged, whatever its values do;
- "converged" within the noise: the three values agree within the measured remeshing noise
  (fTetWild gives a different mesh for the same input; ``femstudy sweep`` remeshes one size
  again to measure how much the quantity moves), with the noise as its uncertainty (changes
  below it are not resolved), which must itself be at most :data:`GCI_CONVERGED` (else
  "converging": a noise that large hides whether it converges);
- oscillatory convergence: the changes alternate in sign with a shrinking swing
  (−1 < R = ε21/ε32 < 0): no order or extrapolation is defined, and the uncertainty is half the
  range of the three values (Stern et al. 2001, J Fluids Eng 123:793–802), "converged" when
  that is at most :data:`GCI_CONVERGED`, else "converging";
- "not converging": the changes alternate in sign without shrinking (R ≤ −1) or grow beyond
  the noise (R at or above ln r21 / ln r32), there is no observed order, or it is under a
  quarter of the formal one;
- "converged" when monotone with GCI_fine ≤ :data:`GCI_CONVERGED` and an observed order no
  higher than the formal one (within 10 %), else "converging": an order above the formal one
  means the meshes are not in the asymptotic range (or errors cancel), and the GCI computed with
  the formal order and the safety factor 3 is then a band, not a verdict.

Within the noise, and in oscillatory convergence, no order is claimed (``observed_order`` is
None): changes that small, or that alternate, do not resolve one.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace

import numpy as np

#: GCI_fine at or below which a monotonely converging quantity is "converged".
GCI_CONVERGED = 0.05


@dataclass(frozen=True)
class Assessment:
    """Convergence of one quantity from the three finest meshes; ``observed_order`` as found,
    ``order_used`` the capped one behind ``extrapolated`` and ``gci_fine``."""

    quantity: str
    h: tuple[float, float, float]
    values: tuple[float, float, float]
    ratio_R: float
    observed_order: float | None
    order_used: float | None
    extrapolated: float | None
    gci_fine: float | None
    noise: float
    verdict: str
    reason: str

    def as_dict(self) -> dict:
        return asdict(self)


#: Largest apparent order the fixed-point iteration follows; beyond it (the iteration diverges
#: when the two refinement ratios differ and the changes barely shrink) the order is undefined.
MAX_ORDER = 100.0


def observed_order(phi, h, max_iter: int = 200, tol: float = 1e-12) -> float | None:
    """Apparent order p from three solutions (fine to coarse), or None if undefined (Celik et
    al. 2008's fixed-point iteration for unequal refinement ratios)."""
    (f1, f2, f3), (h1, h2, h3) = phi, h
    e21, e32 = f2 - f1, f3 - f2
    if e21 == 0 or e32 == 0:
        return None
    r21, r32 = h2 / h1, h3 / h2
    s = math.copysign(1.0, e32 / e21)
    p = abs(math.log(abs(e32 / e21))) / math.log(r21)
    for _ in range(max_iter):
        denominator = r32 ** p - s
        if denominator == 0:  # p = 0 with monotone changes: no order (equal changes on a ladder of equal ratios)
            return None
        q_arg = (r21 ** p - s) / denominator
        if q_arg <= 0:
            return None
        new = abs(math.log(abs(e32 / e21)) + math.log(q_arg)) / math.log(r21)
        if new > MAX_ORDER:
            return None
        if abs(new - p) < tol:
            return new
        p = new
    return p


def assess(quantity: str, h, values, formal_order: float, singular: bool = False, noise: float = 0.0) -> Assessment:
    """Assess convergence of ``values`` (same order as ``h``; the three finest are used).

    Parameters
    ----------
    formal_order : float
        The element's order for the quantity (3 for P2 displacements, 2 for P2 stresses…).
    singular : bool
        The quantity is singular in the continuum: never "converged".
    noise : float
        Relative remeshing noise of the quantity (a change that small is no change).

    Returns
    -------
    Assessment
    """
    order = np.argsort(h)[:3]
    hh = tuple(float(h[i]) for i in order)
    vv = tuple(float(values[i]) for i in order)
    f1, f2, f3 = vv
    e21, e32 = f2 - f1, f3 - f2
    R = e21 / e32 if e32 != 0 else math.inf
    bound = math.log(hh[1] / hh[0]) / math.log(hh[2] / hh[1])
    p = observed_order(vv, hh)
    spread = (max(vv) - min(vv)) / abs(f1) if f1 != 0 else (0.0 if max(vv) == min(vv) else math.inf)

    def result(verdict, reason, used=None, extrapolated=None, gci=None):
        return Assessment(quantity, hh, vv, R, p, used, extrapolated, gci, noise, verdict, reason)

    order_text = "no observed order" if p is None else f"observed order {p:.2f} (formal {formal_order:g})"
    if singular:
        return result("singular", f"singular in the continuum (a load edge or re-entrant corner): it grows as the "
                                  f"mesh is refined and is never converged; {order_text}, spread {100 * spread:.2g} %")
    apparent = "" if p is None else f"; apparent order {p:.2f}, not resolved"
    if spread <= noise:  # changes below the noise are not resolved: the noise bounds what is known
        return replace(result("converged" if noise <= GCI_CONVERGED else "converging",
                              f"the three finest values agree within {100 * spread:.2f} %, inside the "
                              f"{100 * noise:.2f} % remeshing noise (meshes of one size differ that much){apparent}; "
                              "GCI column: that noise", extrapolated=f1, gci=noise), observed_order=None)
    if R < 0:
        if R > -1:  # oscillatory convergence: the swing shrinks under refinement
            u = 0.5 * spread
            return replace(result("converged" if u <= GCI_CONVERGED else "converging",
                                  f"oscillating with a shrinking swing (R = {R:.3g}, |R| < 1): oscillatory "
                                  f"convergence{apparent}, uncertainty half the range of the three values, "
                                  f"{100 * u:.2g} % (GCI column)", gci=u), observed_order=None)
        return result("not converging", f"oscillating (R = {R:.3g}, |R| >= 1) by more than the {100 * noise:.2f} % "
                                        "remeshing noise: the change alternates in sign and does not shrink")
    if R >= bound:
        return result("not converging", f"diverging (R = {R:.3g} >= {bound:.3g}): the change does not shrink under "
                                        "refinement")
    if p is None:
        return result("not converging", "no observed order: the two finest values are equal but the coarser one "
                                        "differs, or the order equation has no solution")
    if p < 0.25 * formal_order:
        return result("not converging", f"{order_text}: far below the formal order")
    used = min(max(p, 0.5), formal_order)
    safety = 1.25 if abs(p - formal_order) <= 0.1 * formal_order else 3.0
    r21 = hh[1] / hh[0]
    extrapolated = (r21 ** used * f1 - f2) / (r21 ** used - 1)
    gci = safety * abs((f1 - f2) / f1) / (r21 ** used - 1) if f1 != 0 else None
    above = p > 1.1 * formal_order
    flag = (f"; above the formal order, not in the asymptotic range: GCI with order {used:g} and safety factor "
            f"{safety:g} is a band, not a verdict" if above else
            f"; safety factor {safety:g}" if safety != 1.25 else "")
    verdict = "converged" if gci is not None and gci <= GCI_CONVERGED and not above else "converging"
    return result(verdict, f"monotone (R = {R:.3g} < {bound:.3g}), {order_text}{flag}", used, extrapolated, gci)


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
