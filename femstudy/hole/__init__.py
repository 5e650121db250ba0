"""The drilled hole as a local model (submodel) around the drill axis.

A global femur model without the hole gives displacements on the cut boundary of a local
model that carries the exact hole — a cylinder of the drill's diameter ending in the drill-point
cone — advancing through depth stations, fine graded elements and the drill's loads on the
hole (docs/hole.md). Modules:

* :mod:`.frame`     the local frame (entry point, drill axis);
* :mod:`.rings`     the 2-D disk triangulation conforming to the hole circle;
* :mod:`.prisms`    prisms into tetrahedra by the minimum-index rule;
* :mod:`.mesh`      the column mesh with depth stations (:func:`hole_mesh`, :class:`HoleMesh`);
* :mod:`.femur`     top/bottom/region callables by ray casting on a femur mesh;
* :mod:`.loads`     unit cutting and chip-evacuation loads on a station's hole;
* :mod:`.dirichlet` solves with prescribed displacements (the submodel's cut boundary);
* :mod:`.probe`     displacement and stress at arbitrary points;
* :mod:`.samples`   points at given distances from the hole surface;

Typical use::

    hole = hole_mesh(HoleFrame.along(entry, direction), 2.7, 90.0, 8.0, tips, top, bottom, region)
    station = hole.at_station(k)
    system = assemble(station.mesh, materials, order=2)
    loads = hole_loads(system, station, growth_exponent=p)
    u = factorize_prescribed(system, cut_dofs).solve(cut_values, loads.patterns)
    stress = point_probe(system, offset_samples(station, 1.0).points).stress(u)
"""

from femstudy.hole.dirichlet import (PrescribedSystem, facet_indices, facet_nodes, factorize_prescribed, node_dofs,
                                     solve_prescribed)
from femstudy.hole.frame import HoleFrame
from femstudy.hole.loads import HoleLoads, facet_quadrature, hole_loads
from femstudy.hole.mesh import CUT_LABELS, LABELS, HoleMesh, HoleStation, Resolution, hole_mesh
from femstudy.hole.probe import PointProbe, point_probe
from femstudy.hole.samples import OffsetSamples, offset_samples

__all__ = ["PrescribedSystem", "facet_indices", "facet_nodes", "factorize_prescribed", "node_dofs", "solve_prescribed", "HoleFrame", "HoleLoads",
           "facet_quadrature", "hole_loads", "CUT_LABELS", "LABELS", "HoleMesh", "HoleStation", "Resolution",
           "hole_mesh", "PointProbe", "point_probe", "OffsetSamples", "offset_samples"]
