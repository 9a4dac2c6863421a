"""Register map used by the device client: one `Register` per name, from the
generated module `facette.device.registers` (contract 2).

While that module is not generated yet (fresh checkout before `make generate`),
the map is read from ``protocol/registers.toml`` directly (same source of
truth); the definition hash is then unknown and the client says so.
"""
from __future__ import annotations

import dataclasses
import importlib
from pathlib import Path

__all__ = ["Register", "RegisterMap", "load_map"]

_WIDTH = {"u16": 1, "i16": 1, "u32": 2}


@dataclasses.dataclass(frozen=True)
class Register:
    """One register (or array of registers).

    name, space ("input" | "holding"), address (first), type ("u16" | "i16" | "u32"),
    count (1 for scalars), stride (registers between elements), unit, min, max,
    enum (name of the enum or None).
    """
    name: str
    space: str
    address: int
    type: str
    count: int = 1
    stride: int = 1
    unit: str = ""
    min: int | None = None
    max: int | None = None
    enum: str | None = None

    @property
    def width(self):
        return _WIDTH[self.type]

    def address_of(self, index=None):
        if self.count == 1:
            if index not in (None, 0):
                raise IndexError(f"register {self.name} is not an array")
            return self.address
        if index is None or not 0 <= index < self.count:
            raise IndexError(f"register {self.name} needs an index in [0, {self.count}), got {index}")
        return self.address + index * self.stride

    def encode(self, value):
        """Python int → list of 16-bit words (range-checked against min/max)."""
        v = int(value)
        if (self.min is not None and v < self.min) or (self.max is not None and v > self.max):
            raise ValueError(f"{self.name} = {v} is out of range [{self.min}, {self.max}]"
                             + (f" {self.unit}" if self.unit else ""))
        if self.type == "u32":
            if not 0 <= v <= 0xFFFFFFFF:
                raise ValueError(f"{self.name} = {v} does not fit in u32")
            return [(v >> 16) & 0xFFFF, v & 0xFFFF]
        if self.type == "i16":
            if not -32768 <= v <= 32767:
                raise ValueError(f"{self.name} = {v} does not fit in i16")
            return [v & 0xFFFF]
        if not 0 <= v <= 0xFFFF:
            raise ValueError(f"{self.name} = {v} does not fit in u16")
        return [v]

    def decode(self, words):
        """list of 16-bit words (width of the type) → Python int."""
        if self.type == "u32":
            return (int(words[0]) << 16) | int(words[1])
        if self.type == "i16":
            w = int(words[0])
            return w - 0x10000 if w & 0x8000 else w
        return int(words[0])


class RegisterMap:
    """Registers by name, enums by name, and the definition hash (None if unknown)."""

    def __init__(self, registers, enums, definition_hash, source, meta=None):
        self.registers = {r.name: r for r in registers}
        self.enums = enums               # {"state": {"IDLE": 0, ...}, ...}
        self.definition_hash = definition_hash
        self.source = source
        self.meta = meta or {}

    def __getitem__(self, name):
        try:
            return self.registers[name]
        except KeyError:
            raise KeyError(f"no register named {name!r} in the protocol definition") from None

    def __contains__(self, name):
        return name in self.registers

    def enum_value(self, enum, name):
        return self.enums[enum][name]

    def enum_name(self, enum, value):
        for k, v in self.enums.get(enum, {}).items():
            if v == value:
                return k
        return f"{enum}?{value}"


def _from_toml(path):
    import tomllib

    data = tomllib.loads(Path(path).read_text())
    regs = []
    for r in data.get("register", []):
        count = int(r.get("count", 1))
        width = _WIDTH[r["type"]]
        regs.append(Register(r["name"], r["space"], int(r["address"]), r["type"], count,
                             int(r.get("stride", width)), r.get("unit", ""), r.get("min"), r.get("max"),
                             r.get("enum")))
    enums = {k: dict(v) for k, v in data.get("enums", {}).items()}
    return RegisterMap(regs, enums, None, str(path), data.get("meta", {}))


def _snake(name):
    import re
    return re.sub(r"(?<!^)(?=[A-Z])", "_", name).lower()


def _from_module(mod):
    """Adapt the generated module (contract 2): REGISTERS {name: Register(name, space,
    address, type, words, unit, minimum, maximum, default, count, stride, enum, ...)},
    one IntEnum class per enum (State, TimingMode, ...), DEFINITION_HASH, UNLOCK_KEY."""
    import enum as _enum

    regs = []
    for r in mod.REGISTERS.values():
        mn, mx = r.minimum, r.maximum
        regs.append(Register(r.name, r.space, int(r.address), r.type, int(r.count), int(r.stride),
                             r.unit or "", mn, mx, r.enum))
    enums = {}
    for attr in dir(mod):
        obj = getattr(mod, attr)
        if isinstance(obj, type) and issubclass(obj, _enum.IntEnum) and obj is not _enum.IntEnum:
            enums[_snake(attr)] = {m.name: int(m.value) for m in obj}
    meta = {"unlock_key": getattr(mod, "UNLOCK_KEY", 0xCA1B), "unit_id": getattr(mod, "UNIT_ID", 1),
            "baud": getattr(mod, "BAUD", 115200)}
    return RegisterMap(regs, enums, int(mod.DEFINITION_HASH), mod.__name__, meta)


_CACHE = {}


def load_map():
    """The register map (generated module, else the TOML definition)."""
    if "map" in _CACHE:
        return _CACHE["map"]
    try:
        mod = importlib.import_module("facette.device.registers")
    except ImportError:
        mod = None
    if mod is not None and hasattr(mod, "REGISTERS"):
        rmap = _from_module(mod)
    else:
        toml = Path(__file__).resolve().parents[3] / "protocol" / "registers.toml"
        if not toml.is_file():
            raise ImportError("facette.device.registers is not generated and protocol/registers.toml "
                              "is not there: run `make generate` in the source tree")
        rmap = _from_toml(toml)
    _CACHE["map"] = rmap
    return rmap
