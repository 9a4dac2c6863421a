#!/usr/bin/env python3
"""libFuzzer dictionaries for the firmware fuzz targets, from include/fw_registers.h.

frame: every register address (big endian, as in a Modbus request), the unlock
key and the function codes the server knows; seq: the unlock key and the values
of the commands (the seq target picks registers by index, not by address).
Usage: make_dict.py frame|seq FW_REGISTERS_H > OUT.dict
"""
import re
import sys


def tokens(kind, header):
    text = open(header, encoding="utf-8").read()
    key = int(re.search(r"#define FW_UNLOCK_KEY 0x([0-9A-Fa-f]+)u", text).group(1), 16)
    out = [("unlock_key", key.to_bytes(2, "big"))]
    if kind == "frame":
        addrs = sorted({int(a, 16) for a in re.findall(r"^\s*\{0x([0-9A-Fa-f]{4})u, \d+u", text, re.M)})
        out += [(f"reg_{a:04x}", a.to_bytes(2, "big")) for a in addrs]
        out += [(f"fc_{fc:02x}", bytes([fc])) for fc in (0x03, 0x04, 0x06, 0x08, 0x10, 0x2B)]
        out.append(("mei_device_id", b"\x2b\x0e"))
    else:
        cmds = re.findall(r"#define FW_COMMAND_(\w+) (\d+)", text)
        out += [(f"cmd_{name.lower()}", int(v).to_bytes(2, "big")) for name, v in cmds]
    return out


def main(argv):
    if len(argv) != 3 or argv[1] not in ("frame", "seq"):
        sys.exit("usage: make_dict.py frame|seq FW_REGISTERS_H > OUT.dict")
    for name, b in tokens(argv[1], argv[2]):
        print(f'{name}="' + "".join(f"\\x{c:02x}" for c in b) + '"')


if __name__ == "__main__":
    main(sys.argv)
