"""Which points a sweep computes: a mesh-convergence ladder, or a parameter grid/list.

Parameter sweeps are TOML files::

    case = "middiaphysis.toml"          # relative to this file
    name = "feed-speed"                 # results/sweep-<name>/ (default: file name)

    [grid]                              # full factorial over dotted case keys
    "drilling.feed_mm_s" = [1.0, 1.5, 2.0]
    "drilling.spindle_rpm" = [1000, 1500]

    [[point]]                           # and/or an explicit list of points
    "site.position" = 0.2
    "site.direction" = "lateral"

In a mesh-convergence sweep the site's local size and TetWild's envelope scale with the
global size, keeping the case's ratios site_size_mm / size_mm and envelope / size_mm, so that
the meshes refine everywhere together (the premise of Richardson extrapolation). With a fixed
envelope the surface detail it preserves, not the size, sets the elements near the surface:
on the built-in femur at envelope 1e-3, sizes 24, 20 and 16 mm all gave 15,800–16,800 P1
DOFs, while the scaled envelope gives 4,633 tets at 32 mm and 13,558 at 16 mm. The
convergence assessment uses the representative size h = (V / elements)^(1/3), not the
nominal one. With ``loads.application = "hole"`` the drilled-hole model's refinement scales
the same way (case refinement × case size / point size), so its wall element size — the mesh
measure of the hole quantities — halves when the global size does.
"""

from __future__ import annotations

import itertools
from pathlib import Path
from typing import Annotated

import math

from pydantic import BaseModel, ConfigDict, Field, model_validator

from femstudy.casefile import Case, with_overrides
from femstudy.errors import UserError, require
from femstudy.schema import parse_toml
from femstudy.sweeps.execute import Point


#: The remeshed points' envelopes differ by these factors: new TetWild runs of the same request,
#: which with the original make three meshes of one size for the remeshing noise.
REMESH_FACTORS = (1.000001, 1.000002)
#: Most points one sweep runs (each is a mesh or a whole study: seconds to minutes); a larger
#: grid is refused before it is expanded. Split it into several sweeps.
MAX_POINTS = 1000
#: Fewest different sizes a convergence ladder needs: the observed order and the Richardson
#: extrapolation take three (femstudy.sweeps.convergence).
MIN_SIZES = 3


def mesh_points(case: Case, sizes: list[float], orders: list[int], refines: list[str],
                remesh: bool = True) -> list[Point]:
    """One point per (size, order, refinement); with ``remesh``, the middle size twice more
    with its TetWild envelope changed by parts in a million, so that TetWild meshes the same
    request again: the three differ by the remeshing noise. The hole models keep the case's
    refinement at every size (the run verifies them itself): the ladder refines the global mesh
    only, whose field drives them."""
    require(len(sizes) > 0 and all(math.isfinite(s) and s > 0 for s in sizes),
            f"--sizes must be positive lengths in mm, got {sizes}")
    distinct = sorted(set(float(s) for s in sizes), reverse=True)
    require(len(distinct) >= MIN_SIZES, f"a mesh-convergence sweep needs {MIN_SIZES} or more different sizes (the "
                                        f"observed order and the extrapolation take three), got "
                                        f"{', '.join(f'{s:g}' for s in distinct)} mm")
    require(len(distinct) * len(orders) * len(refines) <= MAX_POINTS,
            f"--sizes makes {len(distinct) * len(orders) * len(refines):,} points; a sweep runs at most {MAX_POINTS:,}")
    ratio = case.mesh.site_size_mm / case.mesh.size_mm
    envelope_per_mm = case.mesh.envelope / case.mesh.size_mm
    ladder = sorted(set(sizes), reverse=True)
    again = [ladder[len(ladder) // 2]] if remesh and len(ladder) >= 3 else []
    points = []
    for order, refine in itertools.product(orders, refines):
        for size, factor in [(s, 1.0) for s in ladder] + [(s, f) for s in again for f in REMESH_FACTORS]:
            overrides = {"mesh.size_mm": float(size), "mesh.order": order, "mesh.refine": refine,
                         "mesh.envelope": min(0.05, round(float(size) * envelope_per_mm * factor, 12))}
            if refine == "site":
                overrides["mesh.site_size_mm"] = round(float(size) * ratio, 6)
            points.append(Point("mesh", overrides,
                                label=f"P{order} {refine} {size:g} mm" + (f" (remeshed {REMESH_FACTORS.index(factor) + 1})"
                                                                          if factor != 1 else "")))
    for p in points:  # validate every point before any work
        with_overrides(case, p.overrides)
    return points


class SweepFile(BaseModel):
    """A parameter-sweep file: the case it sweeps, its name, a full-factorial ``[grid]`` and/or
    explicit ``[[point]]`` tables of dotted case keys."""

    model_config = ConfigDict(extra="forbid", frozen=True)

    case: str
    name: str | None = None
    grid: dict[str, Annotated[list, Field(min_length=1)]] = {}
    point: list[Annotated[dict, Field(min_length=1)]] = []

    @model_validator(mode="after")
    def _some_points(self):
        if not self.grid and not self.point:
            raise ValueError("give a [grid] or at least one [[point]]")
        return self


def read_parameter_sweep(path: Path) -> tuple[str, Path, list[Point]]:
    """(name, case file, points) of a parameter-sweep TOML file (:class:`SweepFile`)."""
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"cannot read sweep file {path}: {exc}") from None
    doc = parse_toml(text, SweepFile, str(path))
    case_path = (path.parent / doc.case).resolve()
    count = (math.prod(len(v) for v in doc.grid.values()) if doc.grid else 0) + len(doc.point)
    require(count <= MAX_POINTS, f"sweep file {path} makes {count:,} points ("
                                 + " x ".join(str(len(v)) for v in doc.grid.values())
                                 + (f" + {len(doc.point)}" if doc.point else "")
                                 + f"); a sweep runs at most {MAX_POINTS:,}: split it into several sweeps")
    points = []
    keys = list(doc.grid)
    for combo in itertools.product(*(doc.grid[k] for k in keys)) if keys else []:
        overrides = dict(zip(keys, combo))
        points.append(Point("study", overrides, label=", ".join(f"{k}={v}" for k, v in overrides.items())))
    for overrides in doc.point:
        points.append(Point("study", overrides, label=", ".join(f"{k}={v}" for k, v in overrides.items())))
    return doc.name or path.stem, case_path, points
