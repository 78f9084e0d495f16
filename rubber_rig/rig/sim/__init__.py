"""Simulated servo-hydraulic rig on the other end of the rig bus (in-process thread or separate process)."""
from .controller import SimController
from .plant import Actuator, Sensor
from .specimen import LinearSpecimen, build_specimen

__all__ = ['Actuator', 'LinearSpecimen', 'Sensor', 'SimController', 'build_specimen']
