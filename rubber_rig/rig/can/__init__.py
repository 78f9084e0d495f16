"""CAN side of the rig: the DBC protocol and the host driver over any python-can Bus."""
from .protocol import (
                       DBC_PATH,
                       FAULT_BUS,
                       FAULT_CONTROLLER,
                       FAULT_DISPLACEMENT_LIMIT,
                       FAULT_FORCE_LIMIT,
                       FAULT_NAMES,
                       FAULT_NONE,
                       FAULT_SENSOR,
                       FAULT_STREAM,
                       FAULT_VELOCITY_LIMIT,
                       FAULT_WATCHDOG,
                       STATES,
                       MalformedFrame,
                       Protocol,
                       fault_names,
)

__all__ = ['DBC_PATH', 'FAULT_BUS', 'FAULT_CONTROLLER', 'FAULT_DISPLACEMENT_LIMIT', 'FAULT_FORCE_LIMIT',
           'FAULT_NAMES', 'FAULT_NONE', 'FAULT_SENSOR', 'FAULT_STREAM', 'FAULT_VELOCITY_LIMIT', 'FAULT_WATCHDOG',
           'STATES', 'MalformedFrame', 'Protocol', 'fault_names']
