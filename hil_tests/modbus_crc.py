"""The Modbus CRC-16 the hil tests compute on their own (independent of the firmware's C and of
pymodbus), to build raw frames and to corrupt them on purpose."""


def crc16(data: bytes) -> bytes:
    """Modbus CRC-16 (poly 0xA001 reflected, init 0xFFFF), low byte first."""
    crc = 0xFFFF
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return bytes([crc & 0xFF, crc >> 8])
