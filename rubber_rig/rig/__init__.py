"""The rig: CAN protocol and driver over python-can (rig.can), the simulated servo-hydraulic rig (rig.sim),
configuration, open_rig and the ROS-free run_program. Pure Python (no rclpy).
"""
from .can.driver import DriverStatus, RigDriver, SampleBlock
from .can.protocol import (
                           FAULT_BUS,
                           FAULT_CONTROLLER,
                           FAULT_DISPLACEMENT_LIMIT,
                           FAULT_FORCE_LIMIT,
                           FAULT_NONE,
                           FAULT_SENSOR,
                           FAULT_VELOCITY_LIMIT,
                           FAULT_WATCHDOG,
                           STATES,
                           fault_names,
)
from .config import ConfigError, FaultSpec, RigConfig, SimOptions
from .interface import Rig, open_rig
from .run import RunResult, run_program

__all__ = ['ConfigError', 'FAULT_BUS', 'FAULT_CONTROLLER', 'FAULT_DISPLACEMENT_LIMIT', 'FAULT_FORCE_LIMIT',
           'FAULT_NONE', 'FAULT_SENSOR', 'FAULT_VELOCITY_LIMIT', 'FAULT_WATCHDOG', 'FaultSpec', 'Rig', 'RigConfig',
           'RigDriver', 'DriverStatus', 'RunResult', 'STATES', 'SampleBlock', 'SimOptions', 'fault_names',
           'open_rig', 'run_program']
