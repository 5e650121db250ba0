"""The same recordings written in every delimiter, decimal mark, encoding, unit and file format
give the same diagnosis and the same calibration as the plain comma-separated CSV.

Diagnosis runs through the command line (``femstudy diagnose --json``, its JSON contract) so
that this test does not depend on the diagnosis's internals; calibration through the library
calls of ``femstudy calibrate`` (read, process, calibrate), to compare μ at full precision.
Variants whose samples and metadata read back bit for bit equal to another's (the text
variants: same digits in another dress) are diagnosed and calibrated once: that they read
back identical is asserted, and the same inputs give the same results.
"""

import hashlib
import json
import math

import numpy as np
import pytest

from femstudy import cli
from femstudy.recordings import read_recording, synthesize, write_recording
from femstudy.recordings.dataset import random_effects
from femstudy.recordings.formats.text import TextStyle
from femstudy.recordings.pipeline import calibrate
from femstudy.recordings.processing import process
from femstudy.recordings.formats import registry

#: the variant each new way of writing is compared with first
PLAIN = "comma"
VARIANTS = {
    PLAIN: {"format": "csv"},
    "semicolon": {"format": "csv-semicolon"},
    "tab": {"format": "tsv"},
    "decimal comma": {"format": "decimal-comma"},
    "BOM": {"format": TextStyle(bom=True)},
    "CRLF": {"format": TextStyle(newline="\r\n")},
    "Excel CSV (;, decimal comma, BOM, CRLF)": {"format": "excel-csv"},
    "Kistler-like text": {"format": "dynoware"},
    "ms": {"format": "csv", "time_unit": "ms"},
    "kN": {"format": "csv", "force_unit": "kN"},
    "lbf": {"format": "csv", "force_unit": "lbf"},
    "N·m": {"format": "csv", "torque_unit": "N·m"},
    "TDMS": {"format": "tdms"},
    ".mat": {"format": "mat"},
    ".mat v7.3": {"format": "mat73"},
    ".xlsx": {"format": "xlsx"},
}
#: fitted numbers agree to this relative tolerance: the formats differ by rounding at the 6th
#: significant digit (text) and the units by conversion round-off
RTOL = 1e-4
#: the cut's contact and end are located on a grid finer than a sample: within a quarter sample
TIME_ATOL_S = 0.25 / 250.0  # [s] at RATE_HZ
#: the diagnosis JSON rounds to 4 significant digits (or 4 decimals): one unit in the last
JSON_RTOL, JSON_ATOL = 2e-3, 2e-4
#: Inclusion probabilities are BIC weights over every candidate subset, the losing ones
#: included, whose non-convex fits may settle elsewhere on a 1e-6 change of the data (see
#: ``diagnosis``): a losing mechanism's probability (~0.1) moves by a few 1e-4 between variants.
INCLUSION_ATOL = 5e-3
CONDITIONS = ((1.0, 1000.0), (1.5, 1100.0), (1.75, 1500.0), (2.0, 1500.0))
RATE_HZ = 250.0


def write(path_stem, rec, options):
    fmt = options["format"]
    path = path_stem.with_suffix(registry.writers()[fmt].suffix if isinstance(fmt, str) else ".csv")
    write_recording(path, rec, options.get("torque_unit", "Nmm"), format=fmt,
                    time_unit=options.get("time_unit", "s"), force_unit=options.get("force_unit", "N"))
    return path


def fingerprint(recs) -> str:
    digest = hashlib.sha256()
    for rec in recs:
        for values in (rec.time_s, rec.thrust_N, rec.torque_Nmm):
            digest.update(np.ascontiguousarray(values).tobytes())
        digest.update(repr(sorted(rec.metadata.items())).encode())
    return digest.hexdigest()


def calibration_numbers(recs) -> tuple[list[float], list[float]]:
    """(μ_f, μ_w, F_o, T_o of each run, μ of each condition, power-law coefficients and u1;
    contact and end time of each cut)."""
    result = calibrate([process(r) for r in recs], [], name="variant", holdout=0, neurons=None)
    numbers, times = [], []
    for run in result.runs:
        numbers += [run.fit.mu_f, run.fit.mu_w, run.fit.initial_force_N[0], run.fit.initial_torque_Nmm[0]]
        times += [run.run.phase.contact_s, run.run.phase.end_s]
    for condition in result.conditions:
        numbers += [condition.mu_f, condition.mu_w]
    numbers += [float(v) for v in np.ravel(result.bone.a)] + [float(v) for v in np.ravel(result.bone.b)]
    return numbers + [result.bone.u1_MPa], times


def diagnosis(path, out):
    assert cli.main(["diagnose", str(path), "--model", "allotta", "--json", str(out), "--quiet"]) == 0
    found = json.loads(out.read_text())
    found.pop("seconds", None)
    # the information criterion of every candidate subset, losing ones included: a losing
    # candidate's non-convex fit may settle elsewhere on a 1e-6 change of the data
    found.get("selection", {}).pop("bic", None)
    # the reader's notes (a unit converted, stamps merged) describe each file's own layout
    reading = set(read_recording(path).notes)
    found["notes"] = [n for n in found.get("notes", []) if n not in reading]
    return found


def assert_same_json(a, b, where="diagnosis"):
    if isinstance(a, dict):  # key order aside: the BIC table is sorted by value, and near-ties may swap
        assert sorted(a) == sorted(b), where
        for key in a:
            assert_same_json(a[key], b[key], f"{where}.{key}")
    elif isinstance(a, list):
        assert len(a) == len(b), where
        for k, (x, y) in enumerate(zip(a, b)):
            assert_same_json(x, y, f"{where}[{k}]")
    elif isinstance(a, float) or isinstance(b, float):
        atol = INCLUSION_ATOL if ".inclusion_probability." in where else JSON_ATOL
        assert math.isclose(a, b, rel_tol=JSON_RTOL, abs_tol=atol), (where, a, b)
    elif isinstance(a, str) and any(c.isdigit() for c in a):
        return  # an explanation quoting rounded numbers, compared above as numbers
    else:
        assert a == b, (where, a, b)


@pytest.mark.slow
def test_every_variant_gives_the_same_diagnosis_and_calibration(tmp_path):
    rng = np.random.default_rng(11)
    runs = [synthesize(f, n, cortex_mm=5.0, approach_s=1.0, tail_s=1.0, sample_rate_hz=RATE_HZ, seed=k,
                       effects=random_effects(rng), specimen=f"run {k}") for k, (f, n) in enumerate(CONDITIONS)]
    diagnosed = synthesize(1.5, 1500, cortex_mm=4.0, approach_s=0.8, tail_s=0.6, sample_rate_hz=RATE_HZ, seed=3,
                           mu_f=0.07)
    results: dict[str, tuple] = {}
    cache: dict[str, object] = {}
    for name, options in VARIANTS.items():
        folder = tmp_path / f"v{len(results)}"
        folder.mkdir()
        recs = [read_recording(write(folder / f"run{k}", rec, options)) for k, rec in enumerate(runs)]
        diag_path = write(folder / "diagnosed", diagnosed, options)
        diag_key = fingerprint([read_recording(diag_path)])
        if diag_key not in cache:
            cache[diag_key] = diagnosis(diag_path, folder / "d.json")
        cal_key = fingerprint(recs)
        if cal_key not in cache:
            cache[cal_key] = calibration_numbers(recs)
        results[name] = (cache[diag_key], cache[cal_key])
    plain_diagnosis, plain_calibration = results[PLAIN]
    assert [m["mechanism"] for m in plain_diagnosis["missing_physics"]]  # something to compare: clogging found
    for name, (found, numbers) in results.items():
        assert [m["mechanism"] for m in found["missing_physics"]] == \
            [m["mechanism"] for m in plain_diagnosis["missing_physics"]], name
        assert_same_json(found, plain_diagnosis, name)
        np.testing.assert_allclose(numbers[0], plain_calibration[0], rtol=RTOL, err_msg=name)
        np.testing.assert_allclose(numbers[1], plain_calibration[1], rtol=0, atol=TIME_ATOL_S, err_msg=name)
    distinct = len({id(v) for v in cache.values()})
    assert distinct >= 6  # the units and the binary formats really were computed apart
