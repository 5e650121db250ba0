"""Property-based tests: random valid inputs give finite results, random invalid inputs give
a UserError — never another exception. Examples are bounded so the module runs in seconds."""

import math
import string
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from femstudy.casefile import parse_case
from femstudy.drilling import DrillingConditions, Drill, evaluate, registry, time_grid
from femstudy.errors import UserError
from femstudy.recordings import read_recording

FAST = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
finite = st.floats(allow_nan=False, allow_infinity=False)
anything = st.one_of(st.floats(), st.integers(-10**6, 10**6), st.text(max_size=8), st.booleans(),
                     st.lists(st.floats(allow_nan=False), max_size=4))


# -- load models ----------------------------------------------------------------------------

@FAST
@given(feed=st.floats(0.05, 20), rpm=st.floats(50, 30000), cortex=st.floats(0.2, 15),
       angle=st.floats(20, 170), diameter=st.floats(0.5, 8))
def test_valid_operating_points_give_finite_nonnegative_loads(feed, rpm, cortex, angle, diameter):
    cond = DrillingConditions(feed, rpm, cortex, drill=Drill(diameter_mm=diameter, point_angle_deg=angle),
                              friction_override=(0.2, 0.58))
    t = time_grid(cond, cond.phase_times()["fully in cancellous"] / 50)
    for model in registry.names():
        h = evaluate(model, cond, t)
        assert np.all(np.isfinite(h.thrust_N)) and np.all(h.thrust_N >= 0)
        torque = h.torque_Nmm[~np.isnan(h.torque_Nmm)]
        assert np.all(np.isfinite(torque)) and np.all(torque >= 0)


@FAST
@given(feed=st.one_of(st.floats(max_value=0), st.just(math.nan), st.just(math.inf)),
       rpm=st.floats(1, 5000), cortex=st.floats(-5, 10))
def test_invalid_operating_points_are_user_errors(feed, rpm, cortex):
    try:
        DrillingConditions(feed, rpm, cortex)
    except UserError:
        return
    raise AssertionError("an invalid feed was accepted")


@FAST
@given(angle=st.one_of(st.floats(max_value=0), st.floats(min_value=180), st.just(math.nan)))
def test_invalid_point_angles_are_user_errors(angle):
    try:
        Drill(point_angle_deg=angle)
    except UserError:
        return
    raise AssertionError("an invalid point angle was accepted")


# -- case files -----------------------------------------------------------------------------

SECTIONS = {"mesh": ["size_mm", "site_size_mm", "order", "refine", "size_m"],
            "drilling": ["feed_mm_s", "spindle_rpm", "bone", "depth_mm", "mu_f"],
            "time": ["end_s", "step_s"], "site": ["position", "direction", "name"],
            "materials.cortical": ["youngs_modulus_GPa", "poissons_ratio", "density_kg_m3"],
            "clamps": ["length_mm"], "meshh": ["size_mm"]}


def toml_value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float):
        return "nan" if math.isnan(v) else ("inf" if v == math.inf else "-inf" if v == -math.inf else repr(v))
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    return str(v)


@FAST
@given(st.dictionaries(st.sampled_from(sorted(SECTIONS)), st.dictionaries(st.text(string.ascii_lowercase + "_", min_size=1, max_size=12) | st.sampled_from(sum(SECTIONS.values(), [])), anything, max_size=3), max_size=4))
def test_random_case_files_validate_or_fail_cleanly(doc):
    text = 'name = "fuzz"\n' + "".join(
        f"[{section}]\n" + "".join(f"{key} = {toml_value(value)}\n" for key, value in keys.items())
        for section, keys in doc.items())
    try:
        case = parse_case(text)
    except UserError as exc:
        assert "\n" not in str(exc)
        return
    assert case.mesh.size_mm > 0 and case.time.step_s <= case.time.end_s
    assert 0 < case.drilling.feed_mm_s <= 50


@FAST
@given(size=st.floats(1.0, 64.0), order=st.sampled_from([1, 2]), feed=st.floats(0.1, 50.0),
       turns=st.floats(0.0, 1.0), step=st.floats(1e-4, 1.0), end=st.floats(1.0, 10.0),
       position=st.floats(0.01, 0.99), direction=st.sampled_from(["anterior", "posterior", "lateral", "medial"]),
       modulus=st.floats(0.1, 100.0), nu=st.floats(-0.9, 0.49))
def test_every_valid_case_file_is_accepted(size, order, feed, turns, step, end, position, direction, modulus, nu):
    """Any speed from the one at which the feed advances the drill 1 mm a turn (the most a
    twist drill cuts) up to 100,000 rpm is valid."""
    lowest = max(10.0, 60.0 * feed / 1.0)
    rpm = min(100_000.0, lowest * (100_000.0 / lowest) ** turns)
    text = (f'name = "fuzz"\n[mesh]\nsize_mm = {size!r}\norder = {order}\n[drilling]\nfeed_mm_s = {feed!r}\n'
            f'spindle_rpm = {rpm!r}\n[time]\nstep_s = {step!r}\nend_s = {end!r}\n[site]\nposition = {position!r}\n'
            f'direction = "{direction}"\n[materials.cortical]\nyoungs_modulus_GPa = {modulus!r}\n'
            f'poissons_ratio = {nu!r}\n')
    case = parse_case(text)  # any refusal fails the test
    assert case.mesh.size_mm == size and case.drilling.spindle_rpm == rpm and case.site.direction == direction
    assert case.materials.cortical.youngs_modulus_GPa == modulus


@FAST
@given(st.text(max_size=200))
def test_arbitrary_text_is_never_a_crash(text):
    try:
        parse_case(text)
    except UserError:
        pass


# -- recordings -----------------------------------------------------------------------------

def write(text: str) -> Path:
    handle = tempfile.NamedTemporaryFile("w", suffix=".csv", delete=False, encoding="utf-8")
    handle.write(text)
    handle.close()
    return Path(handle.name)


@FAST
@given(rate=st.floats(100, 5000), duration=st.floats(0.2, 1.5), level=st.floats(1, 100),
       noise=st.floats(0, 5), torque_unit=st.sampled_from(["Nmm", "Nm"]), seed=st.integers(0, 2**16))
def test_valid_recordings_read_back_finite(rate, duration, level, noise, torque_unit, seed):
    """Every one of these is a well-formed recording (several spindle revolutions long): it
    must be read, not refused."""
    rng = np.random.default_rng(seed)
    n = int(duration * rate)
    t = np.arange(n) / rate
    thrust = level * (t > t[n // 3]) + noise * rng.standard_normal(n) + 0.1 * np.sin(t)
    torque = 2 * thrust * (1e-3 if torque_unit == "Nm" else 1.0)
    rows = "\n".join(f"{a:.9g},{b:.6g},{c:.6g}" for a, b, c in zip(t, thrust, torque))
    path = write(f"# feed_mm_s = 1.5\n# spindle_rpm = 1500\ntime_s,thrust_N,torque_{torque_unit}\n{rows}\n")
    try:
        rec = read_recording(path)
    finally:
        path.unlink()
    assert np.all(np.isfinite(rec.thrust_N)) and np.all(np.isfinite(rec.torque_Nmm))
    np.testing.assert_allclose(rec.torque_Nmm, 2 * thrust, rtol=1e-5, atol=1e-4)


@FAST
@given(st.lists(st.lists(st.one_of(finite.map(lambda x: f"{x:.4g}"), st.sampled_from(["nan", "inf", "", "x", "1e999"])),
                         min_size=1, max_size=4), min_size=0, max_size=40),
       st.sampled_from(["time_s,thrust_N", "time_s,thrust_N,torque_Nmm", "time,thrust", "t_s,thrust_N", ""]))
def test_random_recordings_read_or_fail_cleanly(rows, header):
    path = write("# feed_mm_s = 1.5\n# spindle_rpm = 1500\n" + header + "\n" + "\n".join(",".join(r) for r in rows))
    try:
        rec = read_recording(path)
        assert np.all(np.isfinite(rec.thrust_N)) and np.all(np.diff(rec.time_s) > 0)
    except UserError as exc:
        assert "\n" not in str(exc)
    finally:
        path.unlink()


@FAST
@given(st.binary(max_size=400))
def test_random_bytes_are_never_a_crash(data):
    handle = tempfile.NamedTemporaryFile("wb", suffix=".csv", delete=False)
    handle.write(data)
    handle.close()
    try:
        read_recording(handle.name)
    except UserError:
        pass
    finally:
        Path(handle.name).unlink()
