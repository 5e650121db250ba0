"""Verification of the near-hole measures in the run, on the femur and mesh at hand.

Every near-hole measure (:class:`femstudy.hole.measures.HoleMeasure`: the largest von Mises
stress at a distance from the hole, beside its wall or beyond an exclusion radius, and the
smallest load factor to failure over the same points) is judged by refining the local hole
models in the run, on the same geometry (:class:`femstudy.hole.study.HoleSite`): the case's
refinement f, whose values are quoted, between a coarser one, f/r, and a finer one, f·r,
r = :data:`LADDER_RATIO` (for f = 2/3: refinements 1/2, 2/3, 5/6, with 12, 16 and 20 elements
round the hole). The coarser and finer levels are run at the governing stations only — those
where some measure has its maximum (or its smallest margin) at the quoted level — since a
measure's value is its value there. A maximum over a discrete point set also moves when a mesh
of the same size is placed differently; that noise is measured on :data:`REPLICATES`
placements of the coarser level (the local mesh turned about the drill axis by fractions of its
azimuthal step), an upper bound on the quoted level's noise. The three levels and the noise are
judged by :func:`femstudy.convergence.assess` with the formal order of P2 stresses (2); the
estimate is carried to the quoted level (GCI_fine · (h/h_fine)^p for monotone convergence; the
noise or half the oscillation's range at every level), and a measure that does not converge
carries the larger of the spread of its three levels and of its replicates (docs/failure.md).
Units: mm, MPa.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from femstudy.convergence import Assessment, assess
from femstudy.hole.mesh import Resolution

if TYPE_CHECKING:
    from femstudy.hole.study import HoleResult

#: Ratio of the finer level's refinement, and of the quoted one's, to the next coarser one.
LADDER_RATIO = 1.25
#: Placements of the middle level whose spread is the discretisation noise.
REPLICATES = 3
#: Formal order of convergence of P2 stresses.
FORMAL_ORDER = 2.0
#: What each measure is judged on, per loading: the worst station's von Mises stress and margin.
QUANTITIES = ("von_mises_MPa", "margin")
LOADINGS = ("dynamic", "static")


def ladder(refinement: float) -> tuple[float, float, float]:
    """The refinements of the ladder, coarse to fine, with the case's ``refinement`` in the middle."""
    return refinement / LADDER_RATIO, refinement, refinement * LADDER_RATIO


def measure_margin(measure) -> float:
    """The smaller of a measure's stress-criterion and strain-criterion load factors."""
    return min(measure.strength_ratio, measure.strain_ratio)


def worst(result, kind: str, radius_mm: float, quantity: str, loading: str = "dynamic") -> float:
    """A loading's ``quantity`` of one measure over the stations of a
    :class:`~femstudy.hole.study.HoleResult`: the largest von Mises stress, or the smallest margin."""
    found = [m for m in result.measures if m.kind == kind and m.loading == loading
             and abs(m.radius_mm - radius_mm) < 1e-9]
    if quantity == "von_mises_MPa":
        values = [m.von_mises_MPa for m in found if np.isfinite(m.von_mises_MPa)]
        return max(values) if values else math.nan
    values = [measure_margin(m) for m in found if np.isfinite(measure_margin(m))]
    return min(values) if values else math.nan


@dataclass(frozen=True)
class Verdict:
    """One measure's verification.

    kind, radius_mm : the measure; quantity : "von_mises_MPa" or "margin"; loading : "dynamic" or "static"
    h_mm : wall element sizes of the ladder, coarse, quoted, fine [mm]
    values : the quantity at each level (the middle one is the quoted value)
    replicates : the quantity at the coarser level's placements; noise their relative range
    assessment : :class:`femstudy.convergence.Assessment` of the three levels
    """

    kind: str
    radius_mm: float
    quantity: str
    loading: str
    h_mm: tuple
    values: tuple
    replicates: tuple
    noise: float
    assessment: Assessment

    @property
    def quoted(self) -> float:
        return self.values[1]

    @property
    def uncertainty(self) -> float:
        """Relative uncertainty of the quoted value (module docstring)."""
        a = self.assessment
        if a.gci_fine is not None and a.verdict in ("converged", "converging"):
            if a.order_used is None:  # within the noise, or oscillatory: the band holds at every level
                return float(a.gci_fine)
            return float(a.gci_fine) * (self.h_mm[1] / self.h_mm[2]) ** a.order_used
        finite = [v for v in self.values + self.replicates if np.isfinite(v)]
        if not finite or not np.isfinite(self.quoted) or self.quoted == 0:
            return math.inf
        return (max(finite) - min(finite)) / abs(self.quoted)

    @property
    def verdict(self) -> str:
        """The verdict at the quoted level: "converged" when the assessment converged and the
        uncertainty carried to the quoted level is at most 5 %."""
        a = self.assessment
        if a.verdict == "converged" and self.uncertainty > 0.05:
            return "converging"
        return a.verdict

    def band(self) -> tuple[float, float]:
        """(low, high) of the quoted value under its uncertainty (a margin's band comes from the
        stress: a load factor scales as 1 / (1 ± u))."""
        value, u = self.quoted, self.uncertainty
        if not math.isfinite(u):
            return (math.nan, math.nan)
        if self.quantity == "margin":
            return (value / (1 + u), value / (1 - u) if u < 1 else math.inf)
        return (value * (1 - u), value * (1 + u))

    def as_dict(self) -> dict:
        low, high = self.band()
        return {"kind": self.kind, "radius_mm": self.radius_mm, "quantity": self.quantity, "loading": self.loading,
                "verdict": self.verdict, "uncertainty": self.uncertainty, "band": [low, high],
                "h_mm": list(self.h_mm), "values": list(self.values), "replicates": list(self.replicates),
                "noise": self.noise, "assessment_verdict": self.assessment.verdict,
                "observed_order": self.assessment.observed_order, "gci_fine": self.assessment.gci_fine,
                "reason": self.assessment.reason}


@dataclass(frozen=True)
class Verification:
    """The verdicts of every near-hole measure, and what they cost.

    levels : the ladder's refinements, coarse, quoted, fine; replicates_deg : the coarse level's turns
    verdicts : one :class:`Verdict` per measure, quantity and loading
    dofs : the local models' DOFs per level (the coarse and fine levels at the governing stations)
    seconds : wall time of the coarse and fine levels and the replicates [s]
    stations : the governing stations the coarse and fine levels ran at
    failed : why the verification could not be made (its verdicts are then empty)
    kept : read from an earlier run of the same inputs and code (femstudy.kept_answers); ``seconds``
        is then what computing it took
    """

    levels: tuple
    replicates_deg: tuple
    verdicts: tuple
    dofs: tuple
    seconds: float
    stations: tuple = ()
    failed: str = ""
    kept: bool = False

    def of(self, kind: str, radius_mm: float, quantity: str = "von_mises_MPa", loading: str = "dynamic"
           ) -> Verdict | None:
        for v in self.verdicts:
            if (v.kind, v.quantity, v.loading) == (kind, quantity, loading) and abs(v.radius_mm - radius_mm) < 1e-9:
                return v
        return None

    def to_json(self) -> dict:
        return {"levels": list(self.levels), "ladder_ratio": LADDER_RATIO, "replicates_deg": list(self.replicates_deg),
                "stations": list(self.stations), "not_made": self.failed or None,
                "formal_order": FORMAL_ORDER, "dofs": list(self.dofs), "seconds": self.seconds,
                "kept_from_earlier_run": self.kept,
                "measures": [v.as_dict() for v in self.verdicts]}


def governing_stations(result) -> tuple[int, ...]:
    """The stations where some measure of ``result`` has its largest von Mises stress or its
    smallest margin, for either loading."""
    chosen = set()
    keys = {(m.kind, m.radius_mm, m.loading) for m in result.measures}
    for kind, radius, loading in keys:
        found = [m for m in result.measures if (m.kind, m.radius_mm, m.loading) == (kind, radius, loading)]
        stressed = [m for m in found if np.isfinite(m.von_mises_MPa)]
        if stressed:
            chosen.add(max(stressed, key=lambda m: m.von_mises_MPa).station)
        weak = [m for m in found if np.isfinite(measure_margin(m))]
        if weak:
            chosen.add(min(weak, key=measure_margin).station)
    return tuple(sorted(chosen))


def verify(coarse, quoted, fine, turned: list, h_mm: tuple) -> tuple[Verdict, ...]:
    """The verdicts of every measure of ``quoted`` (the case's level's HoleResult) from the
    ``coarse`` and ``fine`` levels' results, the coarse level's ``turned`` placements (its own
    result among them) and the levels' wall element sizes ``h_mm`` (coarse to fine)."""
    options = quoted.options
    sets = ([("distance", r) for r in options.distances_mm] + [("wall", r) for r in options.distances_mm]
            + [("exclusion", r) for r in options.exclusion_radii_mm])
    out = []
    for kind, radius in sets:
        for quantity in QUANTITIES:
            for loading in LOADINGS:
                values = tuple(worst(r, kind, radius, quantity, loading) for r in (coarse, quoted, fine))
                replicates = tuple(worst(r, kind, radius, quantity, loading) for r in turned)
                finite = [v for v in replicates if np.isfinite(v)]
                mean = float(np.mean(finite)) if finite else math.nan
                noise = (max(finite) - min(finite)) / abs(mean) if len(finite) > 1 and mean else 0.0
                if all(np.isfinite(values)):
                    a = assess(f"{kind} {radius:g} mm", h_mm, values, FORMAL_ORDER, noise=noise)
                else:
                    a = Assessment(f"{kind} {radius:g} mm", tuple(h_mm), values, math.nan, None, None, None, None,
                                   noise, "not assessed", "the measure has no points in bone at some level")
                out.append(Verdict(kind, float(radius), quantity, loading, tuple(h_mm), values, replicates, noise, a))
    return tuple(out)


def verify_hole(quoted, run_level, options, site) -> Verification:
    """Run the ladder's coarser and finer levels and the coarser level's placements at the
    governing stations with ``run_level(options, site, stations) -> HoleResult`` and judge every
    measure of ``quoted`` (module docstring)."""
    start = time.perf_counter()
    levels = ladder(options.refinement)
    stations = governing_stations(quoted)
    coarse = run_level(replace(options, refinement=levels[0]), site, stations)
    fine = run_level(replace(options, refinement=levels[2]), site, stations)
    step = 360.0 / Resolution(refinement=levels[0]).scaled["n_wall"]
    turns = tuple(step * k / REPLICATES for k in range(1, REPLICATES))
    turned = [coarse] + [run_level(replace(options, refinement=levels[0]), site.turned(t), stations) for t in turns]
    h = tuple(float(Resolution(refinement=f).scaled["wall_mm"]) for f in levels)
    dofs = tuple(sum(s.dofs for s in r.stations) for r in (coarse, quoted, fine))
    return Verification(levels, (0.0, *turns), verify(coarse, quoted, fine, turned, h), dofs,
                        time.perf_counter() - start, stations)


@dataclass(frozen=True)
class HoleAnalysis:
    """The hole models at the case's refinement and their verification (None when not asked)."""

    result: HoleResult
    verification: Verification | None
    factorisations: int = 0

    def read_back(self) -> HoleAnalysis:
        """This analysis as read from an earlier run (femstudy.kept_answers): its verification says so."""
        return replace(self, verification=None if self.verification is None else replace(self.verification,
                                                                                          kept=True))


def analyse_hole(inputs, femur, system, unit_fields, options, solver: str = "auto", keep=None,
                 verified: bool = True, stations: tuple | None = None) -> HoleAnalysis:
    """The hole models of a study (:func:`femstudy.hole.study.hole_stresses`) and, when
    ``verified``, the verification of every measure (:func:`verify_hole`) on the same geometry;
    ``stations`` restricts them to some stations (:func:`femstudy.hole.study.hole_stresses`)."""
    import logging

    from femstudy.errors import UserError
    from femstudy.hole.study import hole_site, hole_stresses

    from femstudy.hole.probe import MeshLocator

    site = hole_site(inputs, femur, options)
    locator = MeshLocator(system)  # one for every level: the cut nodes are found in the one femur mesh

    def run_level(level_options, level_site, level_stations=stations):
        return hole_stresses(inputs, femur, system, unit_fields, level_options, solver, keep, site=level_site,
                             stations=level_stations, locator=locator)

    runs = []

    def counted(level_options, level_site, level_stations=stations):
        result = run_level(level_options, level_site, level_stations)
        runs.append(result)
        return result

    quoted = counted(options, site)
    if not verified:
        return HoleAnalysis(quoted, None, sum(s.factorisations for s in quoted.stations))
    try:
        verification = verify_hole(quoted, counted, options, site)
    except UserError as exc:  # a level the bone refuses (a local model that no longer fits it)
        logging.getLogger(__name__).warning("the hole models could not be verified: %s", exc)
        return HoleAnalysis(quoted, Verification(ladder(options.refinement), (), (), (), 0.0, (), str(exc)),
                            sum(s.factorisations for r in runs for s in r.stations))
    logging.getLogger(__name__).info(
        "hole models verified: refinements %s and %d placements, %.1f s", ", ".join(f"{f:.3g}" for f in
                                                                                   verification.levels),
        len(verification.replicates_deg), verification.seconds)
    return HoleAnalysis(quoted, verification, sum(s.factorisations for r in runs for s in r.stations))
