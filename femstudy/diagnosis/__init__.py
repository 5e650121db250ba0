"""Missing-physics diagnosis: where a recording departs from a simulation, and which left-out
mechanism (chip clogging, feed pulsation, sensor drift, thermal softening) explains it."""

from femstudy.diagnosis.baseline import ModelSimulation, TraceSimulation
from femstudy.diagnosis.diagnose import Diagnosis, diagnose
from femstudy.diagnosis.inputs import model_simulation, read_simulation
from femstudy.diagnosis.mechanisms import names

#: The catalogue's mechanism names (:mod:`.mechanisms`).
MECHANISMS = names()

__all__ = ["Diagnosis", "diagnose", "MECHANISMS", "ModelSimulation", "TraceSimulation", "model_simulation",
           "read_simulation"]
