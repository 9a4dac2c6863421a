#!/usr/bin/env python3
"""Generate the protocol files from protocol/registers.toml (standard library only).

Writes firmware/include/fw_registers.h, host/facette/device/registers.py and
protocol/PROTOCOL.md. ``--check`` writes nothing and exits 1 when a generated file
differs from what the definition gives (``make check-generated``).

The definition is rejected, with a message naming the register, when names are
duplicated, addresses overlap within a space, a type or enum is unknown, or a
default lies outside its range.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DEFINITION = ROOT / "protocol" / "registers.toml"
OUT_C = ROOT / "firmware" / "include" / "fw_registers.h"
OUT_PY = ROOT / "host" / "facette" / "device" / "registers.py"
OUT_MD = ROOT / "protocol" / "PROTOCOL.md"

TYPES = {"u16": (1, 0, 0xFFFF), "i16": (1, -0x8000, 0x7FFF), "u32": (2, 0, 0xFFFFFFFF)}
SPACES = ("input", "holding")
GENERATOR_VERSION = 1


class DefinitionError(ValueError):
    """The register definition is inconsistent."""


def load(path: Path = DEFINITION) -> dict:
    """Parse and validate the definition; returns it with registers expanded."""
    raw_bytes = path.read_bytes()
    data = tomllib.loads(raw_bytes.decode("utf-8"))
    canonical = json.dumps(data, sort_keys=True, separators=(",", ":")).encode()
    digest = hashlib.sha256(canonical).hexdigest()
    enums = data.get("enums", {})
    regs = []
    names = set()
    used: dict[tuple[str, int], str] = {}
    for r in data.get("register", []):
        name = r.get("name")
        where = f"register {name!r}"
        if not name or not name.replace("_", "a").isalnum() or name[0].isdigit():
            raise DefinitionError(f"{where}: name must be an identifier")
        if name in names:
            raise DefinitionError(f"{where}: duplicate name; rename one of them")
        names.add(name)
        if r.get("space") not in SPACES:
            raise DefinitionError(f"{where}: space must be one of {SPACES}")
        if r.get("type") not in TYPES:
            raise DefinitionError(f"{where}: type must be one of {tuple(TYPES)}")
        words, tmin, tmax = TYPES[r["type"]]
        enum = r.get("enum")
        if enum is not None and enum not in enums:
            raise DefinitionError(f"{where}: unknown enum {enum!r}")
        bits = r.get("bits")
        if bits is not None and bits not in enums:
            raise DefinitionError(f"{where}: unknown enum {bits!r} for bits")
        if enum is not None:
            vmin, vmax = min(enums[enum].values()), max(enums[enum].values())
        else:
            vmin, vmax = tmin, tmax
        vmin = r.get("min", vmin)
        vmax = r.get("max", vmax)
        if not (tmin <= vmin <= vmax <= tmax):
            raise DefinitionError(f"{where}: range [{vmin}, {vmax}] does not fit {r['type']}")
        count = r.get("count", 1)
        stride = r.get("stride", words)
        if count < 1 or stride < words:
            raise DefinitionError(f"{where}: count must be >= 1 and stride >= the type's width")
        default = r.get("default", vmin if vmin > 0 or vmax < 0 else 0)
        defaults = list(default) if isinstance(default, list) else [default] * count
        if len(defaults) != count:
            raise DefinitionError(f"{where}: {len(defaults)} defaults for {count} elements")
        for d in defaults:
            if r["space"] == "holding" and not (vmin <= d <= vmax):
                raise DefinitionError(f"{where}: default {d} outside [{vmin}, {vmax}]")
        addr0 = r.get("address")
        if not isinstance(addr0, int) or addr0 < 0:
            raise DefinitionError(f"{where}: address must be a non-negative integer")
        for i in range(count):
            for w in range(words):
                a = addr0 + i * stride + w
                if a > 0xFFFF:
                    raise DefinitionError(f"{where}: address 0x{a:04X} beyond 0xFFFF")
                key = (r["space"], a)
                if key in used:
                    raise DefinitionError(
                        f"{where}: address 0x{a:04X} ({r['space']}) overlaps {used[key]!r}")
                used[key] = name
        regs.append(dict(
            name=name, space=r["space"], address=addr0, type=r["type"], words=words,
            access="r" if r["space"] == "input" else "rw", unit=r.get("unit", ""),
            min=vmin, max=vmax, defaults=defaults, count=count, stride=stride,
            enum=enum, bits=bits, description=r.get("description", "").strip()))
    for ename, members in enums.items():
        if len(set(members.values())) != len(members):
            raise DefinitionError(f"enum {ename!r}: duplicate values")
    return dict(meta=data.get("meta", {}), enums=enums, registers=regs,
                sha256=digest, hash32=int(digest[:8], 16))


def _c_int(v: int) -> str:
    return f"{v}" if v >= 0 else f"({v})"


def gen_c(d: dict) -> str:
    out = [
        "/* GENERATED by tools/gen_protocol.py from protocol/registers.toml: do not edit.",
        " * Regenerate with `make generate`. */",
        "#ifndef FACETTE_FW_REGISTERS_H",
        "#define FACETTE_FW_REGISTERS_H",
        "",
        "#include <stdint.h>",
        "",
        f"#define FW_GENERATOR_VERSION {GENERATOR_VERSION}",
        f"#define FW_DEFINITION_HASH 0x{d['hash32']:08X}u",
        f"#define FW_PROTOCOL_VERSION {d['meta'].get('protocol_version', 1)}u",
        f"#define FW_UNLOCK_KEY 0x{d['meta'].get('unlock_key', 0):04X}u",
        "",
    ]
    for ename, members in d["enums"].items():
        for k, v in members.items():
            out.append(f"#define FW_{ename.upper()}_{k} {v}")
        out.append("")
    out.append("/* Addresses; arrays take an element index. */")
    for r in d["registers"]:
        n = r["name"].upper()
        if r["count"] == 1:
            out.append(f"#define FW_REG_{n} 0x{r['address']:04X}u")
        else:
            out.append(f"#define FW_REG_{n}(i) ((uint16_t)(0x{r['address']:04X}u + (unsigned)(i) * {r['stride']}u))")
            out.append(f"#define FW_REG_{n}_COUNT {r['count']}u")
    out += ["", "/* Value slots: one per register (a u32 is one slot), arrays consecutive. */",
            "enum {"]
    slot = 0
    for r in d["registers"]:
        out.append(f"    FW_SLOT_{r['name'].upper()} = {slot},")
        slot += r["count"]
    out += [f"    FW_SLOT_COUNT = {slot}", "};", ""]
    out += [
        "typedef enum { FW_REG_U16 = 0, FW_REG_I16 = 1, FW_REG_U32 = 2 } fw_reg_type_t;",
        "typedef enum { FW_SPACE_INPUT = 0, FW_SPACE_HOLDING = 1 } fw_reg_space_t;",
        "typedef struct {",
        "    uint16_t addr;  /* first register */",
        "    uint16_t slot;  /* index into the value store */",
        "    uint8_t type;   /* fw_reg_type_t */",
        "    int32_t min, max, def;",
        "} fw_reg_desc_t;",
        "",
    ]
    for space in SPACES:
        rows = []
        slot = 0
        for r in d["registers"]:
            for i in range(r["count"]):
                if r["space"] == space:
                    rows.append((r["address"] + i * r["stride"], slot + i, r, r["defaults"][i]))
            slot += r["count"]
        rows.sort(key=lambda t: t[0])
        sp = space.upper()
        out.append(f"#define FW_REG_{sp}_COUNT {len(rows)}u")
        out.append(f"#ifdef FW_REGISTERS_IMPL")
        out.append(f"/* Sorted by address (binary search). */")
        out.append(f"static const fw_reg_desc_t fw_reg_{space}_table[FW_REG_{sp}_COUNT] = {{")
        for a, s, r, dflt in rows:
            t = {"u16": "FW_REG_U16", "i16": "FW_REG_I16", "u32": "FW_REG_U32"}[r["type"]]
            mx = r["max"] if r["max"] <= 0x7FFFFFFF else -1  # u32 full range: -1 = no upper bound
            out.append(f"    {{0x{a:04X}u, {s}u, {t}, {_c_int(r['min'])}, {_c_int(mx)}, "
                       f"{_c_int(dflt if dflt <= 0x7FFFFFFF else -1)}}}, /* {r['name']} */")
        out.append("};")
        out.append("#endif")
        out.append("")
    out.append("#endif /* FACETTE_FW_REGISTERS_H */")
    return "\n".join(out) + "\n"


def gen_py(d: dict) -> str:
    out = [
        '"""Register map of the facette rig (GENERATED by tools/gen_protocol.py from',
        'protocol/registers.toml: do not edit; regenerate with ``make generate``).',
        "",
        "``REGISTERS`` maps each name to a :class:`Register`; arrays have ``count`` > 1",
        "and element i lives at ``address + i * stride``. u32 registers span two Modbus",
        "registers, high word first. Input registers are read with function 04, holding",
        "registers with 03 and written with 06 / 16.",
        '"""',
        "from __future__ import annotations",
        "",
        "import enum",
        "from typing import NamedTuple",
        "",
        '__all__ = ["Register", "REGISTERS", "DEFINITION_HASH", "DEFINITION_SHA256",',
        '           "PROTOCOL_VERSION", "UNIT_ID", "BAUD", "UNLOCK_KEY", "VENDOR", "PRODUCT",',
        "           " + ", ".join(f'"{_camel(e)}"' for e in d["enums"]) + ",",
        '           "ENUMS", "address_of", "register", "enum_name", "enum_value"]',
        "",
        f"DEFINITION_SHA256 = {d['sha256']!r}",
        f"DEFINITION_HASH = 0x{d['hash32']:08X}",
        f"PROTOCOL_VERSION = {d['meta'].get('protocol_version', 1)}",
        f"UNIT_ID = {d['meta'].get('unit_id', 1)}",
        f"BAUD = {d['meta'].get('baud', 115200)}",
        f"UNLOCK_KEY = 0x{d['meta'].get('unlock_key', 0):04X}",
        f"VENDOR = {d['meta'].get('vendor', '')!r}",
        f"PRODUCT = {d['meta'].get('product', '')!r}",
        "",
    ]
    for ename, members in d["enums"].items():
        out.append("")
        out.append(f"class {_camel(ename)}(enum.IntEnum):")
        out.append(f'    """Values of enum {ename!r}."""')
        out.append("")
        for k, v in members.items():
            out.append(f"    {k} = {v}")
        out.append("")
    out += [
        "",
        "class Register(NamedTuple):",
        '    """One register (or array of registers) of the map."""',
        "",
        "    name: str",
        "    space: str          # 'input' (function 04) or 'holding' (03/06/16)",
        "    address: int        # first Modbus register of element 0",
        "    type: str           # 'u16', 'i16' or 'u32'",
        "    words: int          # Modbus registers per element",
        "    unit: str",
        "    minimum: int",
        "    maximum: int",
        "    default: tuple      # one value per element",
        "    count: int",
        "    stride: int",
        "    enum: str | None",
        "    description: str",
        "",
        _REGISTER_METHODS,
        "",
        "REGISTERS: dict[str, Register] = {",
    ]
    for r in d["registers"]:
        out.append(
            f"    {r['name']!r}: Register({r['name']!r}, {r['space']!r}, 0x{r['address']:04X}, "
            f"{r['type']!r}, {r['words']}, {r['unit']!r}, {r['min']}, {r['max']}, "
            f"{tuple(r['defaults'])!r}, {r['count']}, {r['stride']}, {r['enum']!r},\n"
            f"             {r['description']!r}),")
    out += [
        "}",
        "",
        "",
        "def address_of(name: str, index: int = 0) -> int:",
        '    """Modbus address of element ``index`` of register ``name``."""',
        "    try:",
        "        reg = REGISTERS[name]",
        "    except KeyError:",
        "        raise ValueError(f\"no register named {name!r}; see protocol/PROTOCOL.md\") from None",
        "    if not 0 <= index < reg.count:",
        "        raise ValueError(f\"{name} has {reg.count} element(s); index {index} is out of range\")",
        "    return reg.address + index * reg.stride",
        "",
        "",
        "ENUMS: dict[str, type[enum.IntEnum]] = {",
    ] + [f"    {e!r}: {_camel(e)}," for e in d["enums"]] + ["}", _LOOKUPS]
    return "\n".join(out) + "\n"


# Methods of the generated Register (the client encodes and decodes words with them).
_REGISTER_METHODS = '''    def address_of(self, index: int | None = None) -> int:
        """Modbus address of element ``index`` (None or 0 for a scalar); IndexError outside."""
        if self.count == 1:
            if index not in (None, 0):
                raise IndexError(f"register {self.name} is not an array")
            return self.address
        if index is None or not 0 <= index < self.count:
            raise IndexError(f"register {self.name} needs an index in [0, {self.count}), got {index}")
        return self.address + index * self.stride

    def encode(self, value: int) -> list[int]:
        """Python int -> list of 16-bit words, range-checked against minimum/maximum."""
        v = int(value)
        if not self.minimum <= v <= self.maximum:
            raise ValueError(f"{self.name} = {v} is out of range [{self.minimum}, {self.maximum}]"
                             + (f" {self.unit}" if self.unit else ""))
        if self.type == "u32":
            return [(v >> 16) & 0xFFFF, v & 0xFFFF]
        return [v & 0xFFFF]

    def decode(self, words) -> int:
        """List of 16-bit words (``words`` of them) -> Python int."""
        if self.type == "u32":
            return (int(words[0]) << 16) | int(words[1])
        w = int(words[0])
        if self.type == "i16" and w & 0x8000:
            return w - 0x10000
        return w
'''

_LOOKUPS = '''

def register(name: str) -> Register:
    """The register called ``name``; KeyError naming it when there is none."""
    try:
        return REGISTERS[name]
    except KeyError:
        raise KeyError(f"no register named {name!r} in the protocol definition") from None


def enum_value(enum_name_: str, member: str) -> int:
    """Value of ``member`` of enum ``enum_name_`` (e.g. ``enum_value("command", "ARM")``)."""
    return int(ENUMS[enum_name_][member])


def enum_name(enum_name_: str, value: int) -> str:
    """Member name of ``value`` in enum ``enum_name_``; ``"<enum>?<value>"`` when unknown."""
    try:
        return ENUMS[enum_name_](int(value)).name
    except (KeyError, ValueError):
        return f"{enum_name_}?{value}"
'''


def _camel(s: str) -> str:
    return "".join(p.capitalize() for p in s.split("_"))


def gen_md(d: dict) -> str:
    m = d["meta"]
    out = [
        "<!-- GENERATED by tools/gen_protocol.py from protocol/registers.toml: do not edit. -->",
        "# facette rig protocol",
        "",
        f"Modbus RTU, {m.get('baud', 115200)} bit/s 8N1, unit id {m.get('unit_id', 1)}. "
        f"Protocol version {m.get('protocol_version', 1)}, definition hash "
        f"`0x{d['hash32']:08X}` (register `definition_hash`; sha256 `{d['sha256']}`).",
        "",
        "## Framing and function codes",
        "",
        "- A frame ends after 3.5 character times of silence (1750 us above 19200 bit/s);",
        "  a frame with an inner gap longer than 1.5 characters (750 us) is discarded.",
        "- A frame with a bad CRC, for another unit id, or shorter than 4 bytes gets no answer.",
        "- Unit id 0 (broadcast): functions 06 and 16 are executed and never answered; other",
        "  functions addressed to 0 are ignored.",
        "- 03 read holding registers, 04 read input registers (quantity 1..125),",
        "  06 write single register, 16 write multiple registers (quantity 1..123),",
        "  08 diagnostics sub-function 0000 (echo), 43/14 read device identification",
        f"  (objects 0 vendor `{m.get('vendor', '')}`, 1 product `{m.get('product', '')}`,",
        "  2 firmware revision; read codes 1 basic, 2 regular, 3 extended, 4 one object;",
        "  conformity level 0x81).",
        "",
        "## Exceptions",
        "",
        "| code | name | when |",
        "|---|---|---|",
        "| 01 | ILLEGAL FUNCTION | function code not listed above; 08 with a sub-function other than 0000; 43 with an MEI type other than 14 |",
        "| 02 | ILLEGAL DATA ADDRESS | a register in the range does not exist in that space; a write covers only one half of a u32 (a u32 is written whole or not at all); 43/14 read code 4 of an object that does not exist |",
        "| 03 | ILLEGAL DATA VALUE | quantity out of range; byte count not 2 x quantity; a value outside the register's range (the whole request is refused, nothing is changed); 43/14 read code not 1..4 |",
        "| 04 | SERVER DEVICE FAILURE | the request is well formed but refused: command not allowed in the current state, calibration locked, a latched fault, inconsistent scan configuration at ARM, flash failure. `last_error` says which |",
        "",
        "Checks run in that order (function, quantity, address, value, execution), as the",
        "Modbus application protocol specification's state diagrams do.",
        "",
        "## Running a scan",
        "",
        "1. Read `definition_hash` and refuse a device whose hash differs from this page's.",
        "2. Write the scan configuration (holding 0x1100..): `n_lights`, `n_exposures`,",
        "   `timing_mode`, `light_order[i]` (LED channel of light i), `light_current_mA[i]`,",
        "   `exposure_time_us[e]`, `exposure_current_mA[e]` (0: the light's current), `settle_us`,",
        "   `gap_us`, `prefocus_us`, `mirror_up_us`, `led_pre_us`, `led_post_us`, `sync_timeout_us`,",
        "   `retries`. Configuration writes are refused (04) while a scan is ARMED/RUNNING/PAUSED.",
        "3. `command` = ARM (checks the whole configuration against `max_current_mA` after gain",
        "   and `max_pulse_us`; refused with 04 and `last_error` = -7 otherwise), then START",
        "   (or press the button: it arms and starts; a second press aborts).",
        "4. Frames run light-major: frame k = light k / n_exposures, exposure k % n_exposures.",
        "   Poll `state`, `frames_done`, `ring_count`; record n (0-based, retries included) is ring",
        "   entry n % `ring_len`, 8 registers from `ring_frame(n % ring_len)`: frame, light,",
        "   exposure, current set, current measured, start_us (u32), flags (bit 0 sync seen, bit 1",
        "   retry, bit 2 valid). Read new records before 16 more are written (one request of",
        "   125 registers reads 15 records).",
        "5. The scan ends in DONE, ABORTED (command or button) or FAULT (`fault_bits`, fault log at",
        "   0x0300; CLEAR_FAULTS returns to IDLE). PAUSE lets the frame in progress finish.",
        "",
        "Frame timeline (t_open = shutter line active; exp = `exposure_time_us[e]`):",
        "",
        "- every mode: focus line held `prefocus_us` (if > 0), then `mirror_up_us` of waiting;",
        "- CAMERA: LED on, `settle_us`, shutter pressed for min(exp, 100 ms); LED off at t_open + exp;",
        "- BULB: LED on, `settle_us`, shutter held exactly exp, LED off with the shutter;",
        "- LED: shutter open, `led_pre_us`, LED on for exactly exp, `led_post_us`, shutter released;",
        "- then the flash-sync check: an edge after t_open and before max(window end, t_open +",
        "  `sync_timeout_us`) counts the frame; otherwise the setting is repeated up to `retries`",
        "  times, then the scan faults with SYNC_MISSED; `gap_us` separates frames.",
        "",
    ]
    for ename, members in d["enums"].items():
        out.append(f"### enum `{ename}`")
        out.append("")
        out.append(" | ".join(f"{v} {k}" for k, v in members.items()))
        out.append("")
    for space, title in (("input", "Input registers (function 04, read-only)"),
                         ("holding", "Holding registers (functions 03, 06, 16)")):
        out += [f"## {title}", "",
                "| address | name | type | unit | range | default | description |",
                "|---|---|---|---|---|---|---|"]
        for r in sorted((r for r in d["registers"] if r["space"] == space),
                        key=lambda r: r["address"]):
            addr = f"0x{r['address']:04X}"
            if r["count"] > 1:
                last = r["address"] + (r["count"] - 1) * r["stride"]
                addr += f"..0x{last:04X} (x{r['count']}, stride {r['stride']})"
            rng = f"{r['min']}..{r['max']}" if r["enum"] is None else f"enum {r['enum']}"
            if r["bits"]:
                rng = f"bits of {r['bits']}"
            dflt = "" if r["space"] == "input" else (
                str(r["defaults"][0]) if len(set(r["defaults"])) == 1 else
                ", ".join(str(x) for x in r["defaults"]))
            desc = r["description"].replace("|", "\\|")
            out.append(f"| {addr} | `{r['name']}` | {r['type']} | {r['unit']} | {rng} | "
                       f"{dflt} | {desc} |")
        out.append("")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true",
                    help="write nothing; exit 1 if a generated file is stale")
    ap.add_argument("--definition", type=Path, default=DEFINITION)
    args = ap.parse_args(argv)
    try:
        d = load(args.definition)
    except DefinitionError as e:
        print(f"gen_protocol: {args.definition}: {e}", file=sys.stderr)
        return 2
    outputs = {OUT_C: gen_c(d), OUT_PY: gen_py(d), OUT_MD: gen_md(d)}
    stale = []
    for path, text in outputs.items():
        current = path.read_text(encoding="utf-8") if path.exists() else None
        if current != text:
            stale.append(path)
            if not args.check:
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_text(text, encoding="utf-8")
    if args.check and stale:
        for p in stale:
            print(f"gen_protocol: {p.relative_to(ROOT)} is stale; run `make generate` "
                  f"and commit the result", file=sys.stderr)
        return 1
    if not args.check:
        for p in stale:
            print(f"gen_protocol: wrote {p.relative_to(ROOT)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
