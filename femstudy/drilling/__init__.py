"""Drilling thrust and torque models: Allotta cutting, chip evacuation, literature models.

The load models are registered (:mod:`femstudy.drilling.registry`): ``registry.names()`` lists
them, :func:`evaluate` evaluates one by name.
"""

from femstudy.drilling import registry
from femstudy.drilling.drill import Drill, feed_per_revolution
from femstudy.drilling.friction import BoneSet, load_bone_set
from femstudy.drilling.history import (DrillingConditions, DynamicContent, LoadHistory, evaluate, load_parts,
                                       time_grid)
from femstudy.drilling.registry import LoadModel, LoadParts

__all__ = ["registry", "Drill", "feed_per_revolution", "BoneSet", "load_bone_set", "DrillingConditions",
           "DynamicContent", "LoadHistory", "evaluate", "load_parts", "time_grid", "LoadModel", "LoadParts"]
