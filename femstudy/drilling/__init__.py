"""Drilling thrust and torque models: Allotta cutting, chip evacuation, literature models."""

from femstudy.drilling.drill import Drill, feed_per_revolution
from femstudy.drilling.friction import BoneSet, load_bone_set
from femstudy.drilling.history import MODELS, DrillingConditions, DynamicContent, LoadHistory, evaluate, time_grid

__all__ = ["Drill", "feed_per_revolution", "BoneSet", "load_bone_set", "MODELS",
           "DrillingConditions", "DynamicContent", "LoadHistory", "evaluate", "time_grid"]
