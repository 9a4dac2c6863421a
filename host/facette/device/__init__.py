"""facette.device: talk to the rig's microcontroller (Modbus RTU over any pyserial URL).

`DeviceClient` reads and writes registers by name; the register map is the generated
``facette.device.registers`` (from protocol/registers.toml). The whole instrument
(``facette.connect("sim" | port | url) -> Rig``) is `facette.scan.rig`.
"""
from facette.device import registers
from facette.device.client import (DeviceClient, DeviceError, DeviceException, DeviceMismatch,
                                   DeviceReset, DeviceTimeout)

__all__ = ["DeviceClient", "DeviceError", "DeviceException",
           "DeviceMismatch", "DeviceReset", "DeviceTimeout", "registers"]
