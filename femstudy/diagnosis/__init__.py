"""Missing-physics diagnosis: where a recording departs from a simulation, and which left-out
mechanism of the catalogue (:mod:`.catalogue`: chip clogging, feed pulsation, sensor drift,
thermal softening) explains it, or what outside the catalogue does."""

from femstudy.diagnosis.baseline import ModelSimulation, TraceSimulation
from femstudy.diagnosis.catalogue import MECHANISMS
from femstudy.diagnosis.diagnose import diagnose
from femstudy.diagnosis.inputs import model_simulation, read_simulation
from femstudy.diagnosis.result import Diagnosis

__all__ = ["Diagnosis", "diagnose", "MECHANISMS", "ModelSimulation", "TraceSimulation", "model_simulation",
           "read_simulation"]
