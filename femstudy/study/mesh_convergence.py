"""Global mesh convergence: what ``femstudy sweep`` measured, picked up by the runs it speaks for.

A mesh-convergence sweep (:mod:`femstudy.sweeps`) refines the global mesh of one case; its
verdicts hold for every run of that case whose answers depend on the same things — the
surface's content and every setting but the mesh sizes. The sweep stores its record in the
cache folder under the SHA-256 of those (:func:`record_key`); a run finds it there by the same
key, never by a path someone typed, and quotes, for its own size, each answer's verdict and
uncertainty: GCI_fine at the sweep's finest size, and at a coarser size of the ladder the
estimate GCI_fine · (h/h_fine)^p carried to it (p the order the assessment used; a verdict
within the noise or of an oscillation keeps its band at every size). A run at a size the sweep
did not mesh, or with other settings, has no record and says so. Units: mm.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

from femstudy import atomic

#: Folder of the records in the cache folder.
FOLDER = "mesh-convergence"
#: Settings a record does not depend on: the sizes it varies, and what only names or describes.
SIZE_KEYS = (("mesh", "size_mm"), ("mesh", "site_size_mm"), ("mesh", "envelope"), ("name",), ("description",),
             ("output",))


def record_key(case, surface_digest: str) -> str:
    """SHA-256 of the surface's content and every case setting but the mesh sizes and the output."""
    data = case.model_dump(mode="json")
    for path in SIZE_KEYS:
        node = data
        for key in path[:-1]:
            node = node.get(key, {})
        node.pop(path[-1], None)
    doc = json.dumps({"surface_sha256": surface_digest, "case": data}, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(doc.encode()).hexdigest()


def write_record(case, surface_digest: str, cache_dir: Path, group: str, assessment: dict, sizes: list[float],
                 command: str) -> Path:
    """Store a sweep's assessment of one (order, refinement) group for the runs it speaks for."""
    path = Path(cache_dir) / FOLDER / f"{record_key(case, surface_digest)}.json"
    atomic.write_text(path, json.dumps({"command": command, "group": group, "sizes_mm": sorted(sizes),
                                        "quantities": assessment.get("quantities", {}),
                                        "remeshing_noise": assessment.get("remeshing_noise", {})},
                                       indent=1, default=float))
    return path


def at_size(entry: dict, h_mm: float) -> tuple[str, float | None]:
    """Verdict and relative uncertainty at the mesh measure ``h_mm`` of one quantity's
    assessment (module docstring)."""
    verdict, gci = entry["verdict"], entry.get("gci_fine")
    if gci is None or verdict not in ("converged", "converging"):
        return verdict, gci
    if entry.get("order_used") is None:  # within the noise, or oscillatory: the band holds at every level
        return verdict, gci
    h_fine = min(entry["h"])
    estimate = gci * (h_mm / h_fine) ** entry["order_used"]
    return ("converged" if verdict == "converged" and estimate <= 0.05 else "converging"), estimate


def find(case, surface_digest: str, cache_dir: Path, size_mm: float, measures: dict) -> dict:
    """What the sweep of this case's settings says at ``size_mm``: ``{"source", "size_mm",
    "quantities": {name: {"verdict", "uncertainty"}}}``; ``measures`` maps each quantity to its
    mesh measure at this run [mm] (the site's element size, or the representative size)."""
    path = Path(cache_dir) / FOLDER / f"{record_key(case, surface_digest)}.json"
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return {"source": "no mesh-convergence sweep of this case's settings is recorded in the cache "
                          f"(femstudy sweep CASE --sizes ... records one, with {size_mm:g} mm among its sizes)",
                "size_mm": size_mm, "quantities": {}}
    if not any(abs(s - size_mm) < 1e-9 for s in record["sizes_mm"]):
        return {"source": f"the recorded sweep ({record['command']}) did not mesh {size_mm:g} mm",
                "size_mm": size_mm, "quantities": {}}
    out = {}
    for name, entry in record["quantities"].items():
        if name in measures:
            verdict, u = at_size(entry, measures[name])
            out[name] = {"verdict": verdict, "uncertainty": u}
    return {"source": record["command"], "size_mm": size_mm, "quantities": out}
