"""The mechanism catalogue: each mechanism is one registered object, and a mechanism registered
from outside (here, in the test alone) is fitted, selected and explained with no edit elsewhere."""

import dataclasses
import math

import numpy as np
import pytest

from femstudy.diagnosis.baseline import TraceSimulation
from femstudy.diagnosis.diagnose import diagnose
from femstudy.diagnosis.mechanisms import Mechanism, Problem, catalogue, mechanism
from femstudy.diagnosis.mechanisms.registry import Parameter, register, unregister
from femstudy.recordings import Effects, Noise, synthesize


def test_the_catalogue_is_the_four_mechanisms_in_order():
    assert [m.name for m in catalogue()] == ["chip_clogging", "feed_pulsation", "sensor_drift", "thermal_softening"]
    assert mechanism("sensor_drift").threshold == 0.001


def _step_factor(problem: Problem, params: dict, t: np.ndarray, t_contact: float) -> np.ndarray:
    """A toy: the loads drop by a fraction ``toy_drop`` halfway through the cut."""
    return 1.0 - params["toy_drop"] * (t > t_contact + problem.cut_s / 2)


TOY = Mechanism(
    name="toy_step", parameters=(Parameter("toy_drop", 0.0, 0.9),),
    seeds=lambda problem, linearisation: [{"toy_drop": 0.1}],
    size=lambda problem, params: params["toy_drop"], threshold=0.02,
    explain=lambda problem, params, bone_mu_w: ({"drop": round(params["toy_drop"], 3)},
                                                f"the loads drop by {100 * params['toy_drop']:.0f} %"),
    factor=_step_factor)


@pytest.fixture
def toy():
    register(TOY)
    yield TOY
    unregister(TOY.name)


def test_a_mechanism_registered_elsewhere_is_fitted_selected_and_explained(toy):
    quiet = Effects(noise=Noise(0.3, 1.0), ripple=None, pulsation=None, drift=None, softening=None)
    rec = synthesize(1.5, 1500, effects=quiet, seed=5)
    contact, stop = rec.metadata["true_contact_s"], rec.metadata["true_retraction_s"]
    dropped = np.where(rec.time_s > contact + (stop - contact) / 2, 0.8, 1.0)  # 20 % less halfway
    recording = dataclasses.replace(rec, thrust_N=rec.thrust_N * dropped, torque_Nmm=rec.torque_Nmm * dropped)
    sim = synthesize(1.5, 1500, effects=Effects.none(), sample_rate_hz=500)
    assert "toy_step" in [m.name for m in catalogue()]
    d = diagnose(recording, TraceSimulation.from_recording(sim, rec.spindle_rpm), float(rec.metadata["cortex_mm"]))
    assert any("toy_step" in s for s in d.fits)
    named = {m.mechanism: m for m in d.mechanisms}
    assert "toy_step" in named, d.to_json()["selection"]
    assert named["toy_step"].parameters["drop"] == pytest.approx(0.2, abs=0.03)
    assert math.isfinite(d.to_json()["selection"]["inclusion_probability"]["toy_step"])


def test_subsets_are_walked_in_catalogue_order():
    """Results must not depend on a set's iteration order (it changes with PYTHONHASHSEED):
    in_order gives the catalogue's order whatever collection it is handed."""
    from femstudy.diagnosis.mechanisms.registry import in_order, names

    every = names()
    assert in_order(frozenset(reversed(every))) == every
    assert in_order({every[-1], every[0]}) == (every[0], every[-1])
    assert in_order(set()) == ()
