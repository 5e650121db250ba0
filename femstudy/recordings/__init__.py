"""Force/torque recordings: reading, synthesis, processing and calibration (thesis ch. 4-5)."""

from femstudy.recordings.reader import Recording, read_recording, write_recording
from femstudy.recordings.synthetic import (Effects, FeedPulsation, Noise, SensorDrift, SpindleRipple,
                                           ThermalSoftening, synthesize)

__all__ = ["Recording", "read_recording", "write_recording", "Effects", "FeedPulsation", "Noise",
           "SensorDrift", "SpindleRipple", "ThermalSoftening", "synthesize"]
