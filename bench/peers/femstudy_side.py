"""femstudy's side of the peer benchmark: the model inputs, and the solver that runs on them.

A *model* file (``model.npz``) holds what femstudy starts from — the region-marked linear tet
mesh, the clamp masks, the drill site, the materials and the load history. From it
:func:`build_peer_case` runs femstudy's assembly, drill patch and clamps and exports the
resulting discrete problem (:class:`PeerCase`) for CalculiX and DOLFINx; ``femstudy_run.py``
times femstudy solving the same model in its own process.

The FE module is chosen by name: ``"femstudy"`` is :mod:`femstudy.fe`, ``"standin"`` the
scikit-fem stand-in :mod:`bench.peers.standin` with the same interface. Only this file
touches the solver's objects, and only these names: ``assemble``, ``drill_patch``, ``clamp``,
``factorize``, ``solve_static(fs, f)``, ``solve_transient(fs, patterns, amplitudes, times_s,
observer=)`` (the observer is :class:`femstudy.fe.StepRecorder`, given every stepped field);
``system.nodes/cells/region/n_dofs/mesh/order``, ``patch.thrust/torque/patterns``, ``bc.fixed``.
"""

from __future__ import annotations

import importlib
import os
from dataclasses import dataclass

import numpy as np

from bench.peers.case import PeerCase
from femstudy.atomic import atomic_path
from femstudy.casefile import MaterialsSpec
from femstudy.femur_mesh import CANCELLOUS_DISTAL, CANCELLOUS_PROXIMAL, CORTICAL, Clamps, DrillSite, TetMesh

FE_MODULES = {"femstudy": "femstudy.fe", "standin": "bench.peers.standin"}
PATCH_RADIUS_MM = 1.35


@dataclass
class Model:
    """femstudy's inputs for one benchmark mesh (units mm, N, N·mm, s)."""

    mesh: TetMesh
    clamps: Clamps
    site: DrillSite
    materials: MaterialsSpec
    times_s: np.ndarray
    thrust_N: np.ndarray
    torque_Nmm: np.ndarray
    static_thrust_N: float
    static_torque_Nmm: float
    patch_radius_mm: float = PATCH_RADIUS_MM

    def save(self, path: str | os.PathLike) -> None:
        s = self.site
        with atomic_path(path) as tmp, open(tmp, "wb") as fh:
            np.savez(fh, points=self.mesh.points, tets=self.mesh.tets, region=self.mesh.region,
                     proximal=self.clamps.proximal, distal=self.clamps.distal, site_name=s.name,
                     entry_point=s.entry_point, outward_normal=s.outward_normal, direction=s.direction,
                     cortical_thickness_mm=s.cortical_thickness_mm,
                     materials_json=self.materials.model_dump_json(), times_s=self.times_s,
                     thrust_N=self.thrust_N, torque_Nmm=self.torque_Nmm,
                     static_thrust_N=self.static_thrust_N, static_torque_Nmm=self.static_torque_Nmm,
                     patch_radius_mm=self.patch_radius_mm)

    @classmethod
    def load(cls, path: str | os.PathLike) -> "Model":
        with np.load(path) as d:
            return cls(mesh=TetMesh(d["points"], d["tets"], d["region"]),
                       clamps=Clamps(d["proximal"], d["distal"]),
                       site=DrillSite(str(d["site_name"]), d["entry_point"], d["outward_normal"],
                                      d["direction"], float(d["cortical_thickness_mm"])),
                       materials=MaterialsSpec.model_validate_json(str(d["materials_json"])),
                       times_s=d["times_s"], thrust_N=d["thrust_N"], torque_Nmm=d["torque_Nmm"],
                       static_thrust_N=float(d["static_thrust_N"]),
                       static_torque_Nmm=float(d["static_torque_Nmm"]),
                       patch_radius_mm=float(d["patch_radius_mm"]))


def fe_module(name: str):
    """The FE module with assemble / drill_patch / clamp / solve_static / solve_transient."""
    return importlib.import_module(FE_MODULES[name])


def setup(fe, model: Model):
    """femstudy's system, drill patch and constraints for ``model``."""
    system = fe.assemble(model.mesh, model.materials.to_fe(), order=2)
    patch = fe.drill_patch(system, model.site, radius_mm=model.patch_radius_mm)
    bc = fe.clamp(system, model.clamps)
    return system, patch, bc


def solve(fe, model: Model, analysis: str, system=None, patch=None, bc=None):
    """``static``: u (3n,) [mm] under F·thrust + T·torque. ``transient``: per-step drill-point
    deflection, maximum deflection over all nodes and over the surface nodes (those CalculiX
    writes; the largest deflection can lie just inside) [mm], and the final field."""
    from femstudy.fe import StepRecorder, deflection_channel, point_channel

    if system is None:
        system, patch, bc = setup(fe, model)
    # a static solve or a lone transient: a single-precision factor, its solves refined to
    # double precision (the transient's Krylov blocks only as far as they need: docs/solver.md)
    fs = fe.factorize(system, bc, **({"precision": "single"} if fe.__name__ == "femstudy.fe" else {}))
    if analysis == "static":
        force = model.static_thrust_N * patch.thrust + model.static_torque_Nmm * patch.torque
        return fe.solve_static(fs, force)
    drill, surface = drill_node(system.nodes, model.site), surface_nodes(system)
    surface_mask = np.zeros(len(system.nodes), bool)
    surface_mask[surface] = True
    selector = np.zeros((3, system.n_dofs))
    selector[np.arange(3), 3 * drill + np.arange(3)] = 1.0
    n = len(model.times_s)
    recorder = StepRecorder([deflection_channel(system, {"surface": surface_mask}),
                             point_channel("drill_point", selector, system.nodes[drill])], n, keep=(n - 1,))
    result = fe.solve_transient(fs, patch.patterns, np.column_stack([model.thrust_N, model.torque_Nmm]),
                                model.times_s, observer=recorder)
    history = recorder.history()
    every = np.arange(n)
    assert np.array_equal(history.recorded_steps, every), "the benchmark compares every step"
    return {"times_s": np.asarray(model.times_s), "drill_point_mm": history["drill_point"].values,
            "max_deflection_mm": history["deflection"].values,
            "surface_max_deflection_mm": history["deflection/surface"].values,
            "u_final": recorder.fields[n - 1], "scheme": result.scheme, "krylov_vectors": result.n_vectors}


def build_peer_case(fe, model: Model) -> PeerCase:
    """Assemble ``model`` with femstudy and export the discrete problem for the peers."""
    if model.materials.cortical_model != "isotropic":
        raise ValueError("the peers are given isotropic materials only; benchmark the isotropic cortex")
    system, patch, bc = setup(fe, model)
    fixed_nodes = np.unique(np.asarray(bc.fixed) // 3)
    if len(bc.fixed) != 3 * len(fixed_nodes):
        raise ValueError("the clamps hold some nodes in only some directions; peers fix whole nodes")
    codes = np.unique(system.region)
    materials = model.materials.to_fe()
    spec = {CORTICAL: materials.cortical, CANCELLOUS_PROXIMAL: materials.cancellous,
            CANCELLOUS_DISTAL: materials.cancellous}
    return PeerCase(nodes=np.asarray(system.nodes), elements=np.asarray(system.cells),
                    region=np.asarray(system.region), material_codes=codes,
                    youngs_modulus_MPa=np.array([spec[c].E_MPa for c in codes]),
                    poissons_ratio=np.array([spec[c].nu for c in codes]),
                    density_t_mm3=np.array([spec[c].density_t_mm3 for c in codes]),
                    fixed_nodes=fixed_nodes, thrust=np.asarray(patch.thrust), torque=np.asarray(patch.torque),
                    static_thrust_N=model.static_thrust_N, static_torque_Nmm=model.static_torque_Nmm,
                    times_s=np.asarray(model.times_s), thrust_N=np.asarray(model.thrust_N),
                    torque_Nmm=np.asarray(model.torque_Nmm), drill_node=drill_node(system.nodes, model.site),
                    watch_nodes=surface_nodes(system))


def drill_node(nodes: np.ndarray, site: DrillSite) -> int:
    """The node nearest the drill entry point."""
    return int(np.argmin(np.linalg.norm(nodes - site.entry_point, axis=1)))


def surface_nodes(system) -> np.ndarray:
    """Nodes on the boundary: the vertices of faces that belong to one element only, and the
    P2 mid-edge nodes of their edges (scikit-fem numbers those after the vertices, in
    ``mesh.edges`` order)."""
    mesh = system.mesh
    vertices = mesh.facets[:, mesh.boundary_facets()].ravel()
    if system.order == 1:
        return np.unique(vertices)
    return np.unique(np.concatenate([vertices, mesh.p.shape[1] + mesh.boundary_edges()]))
