"""facette.device: talk to the rig's microcontroller (Modbus RTU over any pyserial URL).

``facette.connect("sim" | port | url) -> Rig``; the register map is the generated
``facette.device.registers`` (from protocol/registers.toml).
"""
from facette.device import registers
from facette.device.client import (DeviceClient, DeviceError, DeviceException, DeviceMismatch,
                                   DeviceReset, DeviceTimeout)
from facette.device.rig import Rig, RigFault, connect

__all__ = ["connect", "Rig", "RigFault", "DeviceClient", "DeviceError", "DeviceException",
           "DeviceMismatch", "DeviceReset", "DeviceTimeout", "registers"]
