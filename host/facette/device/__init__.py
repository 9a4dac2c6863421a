"""Talking to the rig's microcontroller (Modbus RTU): register map, client, Rig."""
from . import registers

__all__ = ["registers"]
