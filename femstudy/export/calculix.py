"""CalculiX input decks for a P2 tetrahedral model, and readers for CalculiX's results.

The deck makes CalculiX (``ccx``; Abaqus reads the same keywords) solve femstudy's discrete
problem, not a re-modelled one:

* node ``i`` of femstudy's P2 node list (DOFs ``3i, 3i+1, 3i+2`` = x, y, z) is CalculiX node
  ``i + 1``;
* a 10-node tetrahedron in scikit-fem's P2 layout — vertices 0–3, then the mid-edge nodes of
  edges [0,1], [1,2], [0,2], [0,3], [1,3], [2,3] — is a C3D10 element with the same node order
  (C3D10's nodes 5–10 sit on edges (1,2), (2,3), (3,1), (1,4), (2,4), (3,4)); an element of
  negative volume is flipped by swapping vertices 1 and 2 together with their edges;
* one element set, material and solid section per region code;
* fixed nodes held in x, y and z (``*BOUNDARY``);
* *assembled* nodal force vectors [N] as ``*CLOAD`` lines — femstudy's discrete load as it is,
  no re-integration of tractions — scaled in a ``*DYNAMIC`` step by ``*AMPLITUDE`` time
  functions (linear between points, step time). CalculiX refuses two loads with different
  amplitudes on one DOF, so DOFs that several patterns load get an amplitude of their own.

Numbers are written with 14 significant digits: CalculiX reads at most 20 characters per field.

Quadrature: C3D10 integrates stiffness with 4 points, exact for P2 on straight-edged tets, so
static answers agree with an exact P2 assembly to round-off; its mass matrix uses the same
4-point rule, which is *not* exact for P2 (the integrand is of degree 4). A consistent mass
matrix integrated exactly is therefore not CalculiX's: compare transients against a mass
matrix built with a degree-2 (4-point) rule, or expect differences of the order of the
quadrature error in the frequencies.

Units are the inputs' own; femstudy's are mm, N, MPa, tonne/mm³ and s.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Mapping, Protocol, Sequence

import numpy as np

from femstudy.atomic import atomic_path
from femstudy.errors import UserError
from femstudy.femur_mesh import REGION_NAMES

#: C3D10 node k (0-based) is scikit-fem P2 element node C3D10_FROM_SKFEM[k].
C3D10_FROM_SKFEM = np.arange(10)
#: Node permutation that reverses a tet's orientation: swap vertices 1 and 2 and so the
#: edges [0,1]↔[0,2] and [1,3]↔[2,3] (edge [1,2] and [0,3] stay).
_FLIP = np.array([0, 2, 1, 3, 6, 5, 4, 7, 9, 8])


class Material(Protocol):
    """Anything with these attributes, e.g. :class:`femstudy.casefile.MaterialSpec`."""

    youngs_modulus_MPa: float
    poissons_ratio: float
    density_t_mm3: float


@dataclass(frozen=True)
class Isotropic:
    """Isotropic linear elastic material: E [MPa], ν [-], ρ [tonne/mm³]."""

    youngs_modulus_MPa: float
    poissons_ratio: float
    density_t_mm3: float


@dataclass(frozen=True)
class StaticStep:
    """Linear static step: K u = f under one assembled nodal force vector ``force_N`` (3n,)."""

    force_N: np.ndarray


@dataclass(frozen=True)
class DynamicStep:
    """Direct time integration with a fixed step: Newmark average acceleration (HHT α = 0).

    M ü + K u = f(t),  f(t) = Σ_k a_k(t) · patterns[k],  a_k linear between
    (``times_s``, ``amplitudes[k]``) with ``times_s`` counted from the start of the step.
    ``dt_s`` is the fixed increment and ``duration_s`` the step length. The step starts from
    the state the previous step left (at rest for a first step) with the initial acceleration
    CalculiX computes from equilibrium, M a₀ = f(0) − K u₀.
    """

    patterns: Sequence[np.ndarray]
    times_s: np.ndarray
    amplitudes: Sequence[np.ndarray]
    dt_s: float
    duration_s: float

    @property
    def n_increments(self) -> int:
        return int(round(self.duration_s / self.dt_s))


@dataclass(frozen=True)
class NodalHistory:
    """Displacements read back from CalculiX at its output times.

    times_s : (k,) CalculiX total time of each output [s] (a static step ends at 1.0)
    nodes   : (n,) femstudy node indices (0-based) in the order of ``u``
    u       : (k, n, 3) displacements [mm]
    """

    times_s: np.ndarray
    nodes: np.ndarray
    u: np.ndarray = field(repr=False)

    def dof_vector(self, k: int, n_nodes: int) -> np.ndarray:
        """Output ``k`` as a femstudy DOF vector (3·n_nodes,); nodes not written are NaN."""
        full = np.full((n_nodes, 3), np.nan)
        full[self.nodes] = self.u[k]
        return full.ravel()


def c3d10_connectivity(nodes: np.ndarray, elements: np.ndarray) -> np.ndarray:
    """1-based C3D10 node lists (m, 10) for P2 elements in scikit-fem's layout (m, 10).

    Elements whose vertices 0–3 span a negative volume, det[x1−x0, x2−x0, x3−x0] < 0, are
    reordered so that every C3D10 element has a positive Jacobian.
    """
    elements = np.asarray(elements)
    x = nodes[elements[:, :4]]
    det = np.linalg.det(np.stack([x[:, 1] - x[:, 0], x[:, 2] - x[:, 0], x[:, 3] - x[:, 0]], axis=2))
    if np.any(det == 0):
        raise UserError(f"{np.count_nonzero(det == 0)} tetrahedra have zero volume, "
                        "which CalculiX cannot integrate")
    out = elements[:, C3D10_FROM_SKFEM].copy()
    out[det < 0] = out[det < 0][:, _FLIP]
    return out + 1


def write_inp(path: str | os.PathLike, nodes: np.ndarray, elements: np.ndarray,
              region: np.ndarray, materials: Mapping[int, Material], fixed_nodes: np.ndarray,
              steps: Sequence[StaticStep | DynamicStep], *, output_nodes: np.ndarray | None = None,
              dat: bool = True, frd: bool = False, heading: str = "femstudy P2 model") -> Path:
    """Write a CalculiX input deck (atomically) and return its path.

    nodes        : (n, 3) P2 node coordinates [mm], femstudy's node order
    elements     : (m, 10) P2 elements in scikit-fem's layout (0-based node indices)
    region       : (m,) region code of each element; every code needs an entry in ``materials``
    materials    : region code -> E [MPa], ν, ρ [tonne/mm³]
    fixed_nodes  : indices of nodes fixed in x, y and z
    steps        : analysis steps in order; each step's loads replace the previous step's
    output_nodes : nodes whose displacements are written (default: all) — restricting them
                   keeps large transient outputs small
    dat, frd     : write displacements to ``.dat`` (*NODE PRINT, 7 significant digits) and/or
                   ``.frd`` (*NODE FILE, 6 digits; CalculiX GraphiX/ParaView readers)
    """
    nodes = np.asarray(nodes, dtype=float)
    region = np.asarray(region)
    n = len(nodes)
    missing = sorted(set(np.unique(region).tolist()) - set(materials))
    if missing:
        raise UserError(f"no material given for region code(s) {missing}")
    if len(fixed_nodes) == 0:
        raise UserError("no fixed nodes: the CalculiX model would be free to move as a rigid body")
    for step in steps:
        for vector in ([step.force_N] if isinstance(step, StaticStep) else step.patterns):
            if np.shape(vector) != (3 * n,):
                raise UserError(f"a load vector has shape {np.shape(vector)}, expected ({3 * n},) "
                                "= 3 DOFs per P2 node")
    connectivity = c3d10_connectivity(nodes, elements)
    with atomic_path(path) as tmp, open(tmp, "w", encoding="ascii") as f:
        f.write(f"*HEADING\n{heading}\n")
        f.write("*NODE, NSET=NALL\n")
        _write_rows(f, np.column_stack([np.arange(1, n + 1), nodes]), "%d, %.14g, %.14g, %.14g")
        for code in sorted(materials):
            name = _region_name(code)
            members = np.flatnonzero(region == code)
            if len(members) == 0:
                continue
            f.write(f"*ELEMENT, TYPE=C3D10, ELSET={name}\n")
            _write_rows(f, np.column_stack([members + 1, connectivity[members]]),
                        ", ".join(["%d"] * 11))
            mat = materials[code]
            f.write(f"*MATERIAL, NAME=M_{name}\n*ELASTIC\n{mat.youngs_modulus_MPa:.14g}, "
                    f"{mat.poissons_ratio:.14g}\n*DENSITY\n{mat.density_t_mm3:.14g}\n"
                    f"*SOLID SECTION, ELSET={name}, MATERIAL=M_{name}\n")
        _write_set(f, "FIXED", np.asarray(fixed_nodes) + 1)
        f.write("*BOUNDARY\nFIXED, 1, 3\n")
        out_set = "NALL"
        if output_nodes is not None:
            out_set = "OUT"
            _write_set(f, out_set, np.asarray(output_nodes) + 1)
        loads = [_timed_loads(number, step) for number, step in enumerate(steps, start=1)]
        for groups in loads:
            for name, values, _ in groups:
                if name:
                    f.write(f"*AMPLITUDE, NAME={name}\n")
                    _write_flat(f, values, 8, "%.14g")
        energy = any(isinstance(step, DynamicStep) for step in steps[1:])
        if energy:
            f.write("*ELSET, ELSET=ENERGY_PROBE\n1\n")
        for number, groups in enumerate(loads, start=1):
            _write_step(f, number, steps[number - 1], groups, out_set, dat, frd, energy and number == 1)
    return Path(path)


def _timed_loads(number: int, step: StaticStep | DynamicStep) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """(amplitude name, amplitude (t, a) pairs, load vector) for each *CLOAD block of a step.

    A static step has one block without amplitude. In a dynamic step, the DOFs loaded by one
    pattern only take that pattern's amplitude; CalculiX refuses two concentrated loads with
    different amplitudes on one DOF, so a DOF loaded by several patterns gets an amplitude of its
    own, the combined history Σ_k a_k(t) p_k[dof], under a unit load.
    """
    if isinstance(step, StaticStep):
        return [("", np.empty(0), np.asarray(step.force_N, dtype=float))]
    patterns = np.array(step.patterns, dtype=float)
    amplitudes = np.array(step.amplitudes, dtype=float)
    shared = np.count_nonzero(patterns, axis=0) > 1
    groups = []
    for k, pattern in enumerate(patterns):
        own = np.where(shared, 0.0, pattern)
        if np.any(own):
            groups.append((f"A{number}_{k + 1}", np.column_stack([step.times_s, amplitudes[k]]).ravel(), own))
    for dof in np.flatnonzero(shared):
        unit = np.zeros(patterns.shape[1])
        unit[dof] = 1.0
        combined = amplitudes.T @ patterns[:, dof]
        groups.append((f"A{number}_N{dof // 3 + 1}_{dof % 3 + 1}",
                       np.column_stack([step.times_s, combined]).ravel(), unit))
    return groups


def _write_step(f: IO[str], number: int, step: StaticStep | DynamicStep, groups: list, out_set: str,
                dat: bool, frd: bool, energy: bool) -> None:
    if isinstance(step, StaticStep):
        f.write("*STEP\n*STATIC\n")
    else:
        f.write(f"*STEP, INC={step.n_increments + 10}\n*DYNAMIC, DIRECT, ALPHA=0.\n"
                f"{step.dt_s:.14g}, {step.duration_s:.14g}\n")
    if number > 1:
        f.write("*CLOAD, OP=NEW\n")          # the previous step's loads end here
    for name, _, vector in groups:
        _write_cload(f, f"*CLOAD, AMPLITUDE={name}" if name else "*CLOAD", vector)
    if energy:                               # CalculiX: a later *DYNAMIC step needs energy output from step 1
        f.write("*EL PRINT, ELSET=ENERGY_PROBE\nENER\n")
    if dat:
        f.write(f"*NODE PRINT, NSET={out_set}\nU\n")
    if frd:
        f.write(f"*NODE FILE, NSET={out_set}\nU\n")
    f.write("*END STEP\n")


def _write_cload(f: IO[str], keyword: str, vector: np.ndarray) -> None:
    """``node, dof, value`` for every non-zero entry of a DOF vector (3n,)."""
    nonzero = np.flatnonzero(vector)
    f.write(keyword + "\n")
    _write_rows(f, np.column_stack([nonzero // 3 + 1, nonzero % 3 + 1, vector[nonzero]]),
                "%d, %d, %.14g")


def _write_set(f: IO[str], name: str, ids: np.ndarray) -> None:
    f.write(f"*NSET, NSET={name}\n")
    _write_flat(f, np.asarray(ids, dtype=np.int64), 16, "%d")


def _write_flat(f: IO[str], values: np.ndarray, per_line: int, fmt: str) -> None:
    """``values`` as comma-separated data lines of at most ``per_line`` entries."""
    full = len(values) - len(values) % per_line
    _write_rows(f, values[:full].reshape(-1, per_line), ", ".join([fmt] * per_line))
    if len(values) > full:
        f.write(", ".join(fmt % v for v in values[full:]) + "\n")


def _write_rows(f: IO[str], rows: np.ndarray, fmt: str) -> None:
    if len(rows):
        np.savetxt(f, rows, fmt=fmt)


def _region_name(code: int) -> str:
    return REGION_NAMES.get(int(code), f"region_{int(code)}").upper()


def run_ccx(inp: str | os.PathLike, threads: int = 2, timeout: float | None = None
            ) -> subprocess.CompletedProcess:
    """Run ``ccx -i JOB`` in the deck's folder; raise if ccx is missing or reports an error."""
    ccx = shutil.which("ccx")
    if ccx is None:
        raise UserError("ccx (CalculiX) is not on PATH; install it with bench/peers/setup.sh")
    inp = Path(inp)
    # ccx takes its thread counts from its environment: set them for it alone, through env(1)
    command = ["env", f"OMP_NUM_THREADS={threads}", f"CCX_NPROC_EQUATION_SOLVER={threads}", ccx, "-i", inp.stem]
    proc = subprocess.run(command, cwd=inp.parent, capture_output=True, text=True, timeout=timeout)
    errors = [line for line in proc.stdout.splitlines() if "*ERROR" in line]
    if proc.returncode != 0 or errors:
        raise RuntimeError(f"ccx failed on {inp} (exit {proc.returncode}): "
                           + ("; ".join(errors[:3]) or proc.stderr.strip()[-500:]))
    return proc


_DAT_HEADER = re.compile(r"^\s*displacements \(vx,vy,vz\) for set (\S+) and time\s+(\S+)")


def read_dat_displacements(path: str | os.PathLike) -> NodalHistory:
    """Displacement blocks of a ``.dat`` file (*NODE PRINT ... U), 7 significant digits."""
    times, blocks = [], []
    current = None
    with open(path, encoding="ascii", errors="replace") as f:
        for line in f:
            header = _DAT_HEADER.match(line)
            if header:
                times.append(float(header.group(2)))
                current = []
                blocks.append(current)
            elif current is not None:
                parts = line.split()
                if len(parts) == 4 and parts[0].isdigit():
                    current.append(parts)
                elif parts:                  # any other block ends this one
                    current = None
    return _history(path, times, blocks)


def read_frd_displacements(path: str | os.PathLike) -> NodalHistory:
    """``DISP`` blocks of an ASCII ``.frd`` file (fixed-width, 6 significant digits)."""
    times, blocks = [], []
    time, current = None, None
    with open(path, encoding="ascii", errors="replace") as f:
        for line in f:
            if line.startswith("  100C"):
                time = float(line[12:24])
            elif line.startswith(" -4  DISP"):
                current = []
                blocks.append(current)
                times.append(time)
            elif current is not None:
                if line.startswith(" -1"):
                    current.append((line[3:13], line[13:25], line[25:37], line[37:49]))
                elif line.startswith(" -3"):
                    current = None
    return _history(path, times, blocks)


def _history(path, times: list, blocks: list) -> NodalHistory:
    if not blocks:
        raise UserError(f"{path} holds no displacement output")
    ids = np.array([int(row[0]) for row in blocks[0]])
    u = np.empty((len(blocks), len(ids), 3))
    for k, block in enumerate(blocks):
        if len(block) != len(ids):
            raise UserError(f"{path}: output {k + 1} has {len(block)} nodes, the first has {len(ids)}")
        u[k] = np.array([row[1:] for row in block], dtype=float)
    return NodalHistory(times_s=np.array(times, dtype=float), nodes=ids - 1, u=u)
