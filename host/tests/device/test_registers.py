"""The generated register module, the generator's checks, and the golden frames.

The CRC here is computed independently of the firmware (bitwise, from the Modbus
specification); every golden frame is checked byte for byte against it and against
the register map.
"""
from __future__ import annotations

import hashlib
import json
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from facette.device import registers as R

ROOT = Path(__file__).resolve().parents[3]
VECTORS = ROOT / "protocol" / "vectors"
GEN = ROOT / "tools" / "gen_protocol.py"
sys.path.insert(0, str(ROOT / "tools"))
import gen_protocol  # noqa: E402  (tools/ is not a package)


def crc16(data: bytes) -> bytes:
    crc = 0xFFFF
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
    return bytes([crc & 0xFF, crc >> 8])


def pairs(path: Path):
    """(description, request, answer or None) of a vector file."""
    desc, req = "", None
    for line in path.read_text().splitlines():
        if line.startswith("#"):
            desc = line[2:]
        elif line.startswith(">"):
            req = bytes.fromhex(line[1:])
        elif line.startswith("<"):
            ans = line[1:].strip()
            yield desc, req, None if ans == "-" else bytes.fromhex(ans)


ALL_PAIRS = [(p.name, *t) for p in sorted(VECTORS.glob("*.hex")) for t in pairs(p)]


def test_crc_of_the_specification_example():
    assert crc16(bytes.fromhex("01030000000A")) == bytes.fromhex("C5CD")


def test_generated_files_are_up_to_date():
    r = subprocess.run([sys.executable, str(GEN), "--check"], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr


def test_definition_hash_is_the_sha256_of_the_definition():
    data = tomllib.loads((ROOT / "protocol" / "registers.toml").read_text())
    digest = hashlib.sha256(json.dumps(data, sort_keys=True, separators=(",", ":")).encode()).hexdigest()
    assert R.DEFINITION_SHA256 == digest
    assert R.DEFINITION_HASH == int(digest[:8], 16)
    header = (ROOT / "firmware" / "include" / "fw_registers.h").read_text()
    assert f"#define FW_DEFINITION_HASH 0x{R.DEFINITION_HASH:08X}u" in header


def test_no_two_registers_share_an_address():
    seen = {}
    for reg in R.REGISTERS.values():
        for i in range(reg.count):
            for w in range(reg.words):
                key = (reg.space, reg.address + i * reg.stride + w)
                assert key not in seen, f"{reg.name} overlaps {seen[key]}"
                seen[key] = reg.name


def test_defaults_lie_in_their_ranges_and_u32_take_two_words():
    for reg in R.REGISTERS.values():
        assert reg.words == (2 if reg.type == "u32" else 1)
        assert len(reg.default) == reg.count
        if reg.space == "holding":
            assert all(reg.minimum <= d <= reg.maximum for d in reg.default), reg.name


def test_address_of_arrays_and_errors():
    assert R.address_of("ring_flags", 3) == 0x0207 + 3 * 8
    assert R.address_of("exposure_time_us", 15) == 0x1140 + 30
    with pytest.raises(ValueError, match="no register named"):
        R.address_of("nope")
    with pytest.raises(ValueError, match="16 element"):
        R.address_of("light_order", 16)


def _write_definition(tmp_path, registers: str) -> Path:
    p = tmp_path / "r.toml"
    p.write_text('[meta]\nprotocol_version = 1\n[enums.x]\nA = 0\n' + registers)
    return p


@pytest.mark.parametrize("body, message", [
    ('[[register]]\nname="a"\nspace="input"\naddress=1\ntype="u16"\n'
     '[[register]]\nname="a"\nspace="input"\naddress=2\ntype="u16"\n', "duplicate name"),
    ('[[register]]\nname="a"\nspace="input"\naddress=1\ntype="u32"\n'
     '[[register]]\nname="b"\nspace="input"\naddress=2\ntype="u16"\n', "overlaps 'a'"),
    ('[[register]]\nname="a"\nspace="holding"\naddress=0\ntype="u16"\ncount=4\nstride=2\n'
     '[[register]]\nname="b"\nspace="holding"\naddress=6\ntype="u16"\n', "overlaps 'a'"),
    ('[[register]]\nname="a"\nspace="holding"\naddress=1\ntype="u16"\nmin=1\nmax=3\ndefault=9\n',
     "outside"),
    ('[[register]]\nname="a"\nspace="input"\naddress=1\ntype="u8"\n', "type must be"),
    ('[[register]]\nname="a"\nspace="coil"\naddress=1\ntype="u16"\n', "space must be"),
    ('[[register]]\nname="a"\nspace="input"\naddress=1\ntype="u16"\nenum="nope"\n', "unknown enum"),
    ('[[register]]\nname="a"\nspace="input"\naddress=1\ntype="i16"\nmin=-40000\n', "does not fit"),
])
def test_generator_rejects_inconsistent_definitions(tmp_path, body, message):
    with pytest.raises(gen_protocol.DefinitionError, match=message):
        gen_protocol.load(_write_definition(tmp_path, body))


def test_generator_check_mode_reports_a_stale_file(tmp_path):
    bad = _write_definition(tmp_path, '[[register]]\nname="a"\nspace="input"\naddress=1\ntype="u16"\n')
    r = subprocess.run([sys.executable, str(GEN), "--check", "--definition", str(bad)],
                       capture_output=True, text=True)
    assert r.returncode == 1 and "is stale" in r.stderr


def test_vector_files_are_present():
    names = {p.name for p in VECTORS.glob("*.hex")}
    assert {"functions.hex", "exceptions.hex", "addressing.hex"} <= names
    assert len(ALL_PAIRS) > 40


@pytest.mark.parametrize("name, desc, req, ans", ALL_PAIRS,
                         ids=[f"{n}:{i}" for i, (n, *_r) in enumerate(ALL_PAIRS)])
def test_golden_frame_crcs_and_shapes(name, desc, req, ans):
    bad_crc_vector = "bad CRC" in desc or "shorter than 4" in desc
    if not bad_crc_vector:
        assert req[-2:] == crc16(req[:-2]), f"{desc}: request CRC should be {crc16(req[:-2]).hex()}"
    if ans is None:
        assert bad_crc_vector or req[0] != R.UNIT_ID or "broadcast" in desc
        return
    assert ans[-2:] == crc16(ans[:-2]), f"{desc}: answer CRC should be {crc16(ans[:-2]).hex()}"
    assert ans[0] == req[0] == R.UNIT_ID
    fc = req[1]
    if ans[1] & 0x80:
        assert ans[1] == fc | 0x80 and 1 <= ans[2] <= 4 and len(ans) == 5
        assert f"{ans[2]:02d}" in desc or "last_error" in desc or desc.startswith("0")
        return
    assert ans[1] == fc
    if fc in (3, 4):
        space = "holding" if fc == 3 else "input"
        start, qty = int.from_bytes(req[2:4], "big"), int.from_bytes(req[4:6], "big")
        assert ans[2] == 2 * qty and len(ans) == 5 + 2 * qty
        words = {}
        for reg in R.REGISTERS.values():
            if reg.space == space:
                for i in range(reg.count):
                    for w in range(reg.words):
                        words[reg.address + i * reg.stride + w] = reg
        assert all(a in words for a in range(start, start + qty)), desc
    elif fc in (6, 16):
        assert ans[:6] == req[:6]


def test_golden_default_reads_match_the_register_defaults():
    """The fresh-device reads of functions.hex agree with the generated defaults."""
    (_, _, req, ans) = next(p for p in ALL_PAIRS if p[0] == "functions.hex" and p[2][1] == 3
                            and p[2][2:4] == b"\x11\x00")
    values = [int.from_bytes(ans[3 + 2 * i: 5 + 2 * i], "big") for i in range(ans[2] // 2)]
    assert values == [R.REGISTERS["n_lights"].default[0], R.REGISTERS["n_exposures"].default[0],
                      R.REGISTERS["timing_mode"].default[0]]


def test_generated_module_and_toml_describe_the_same_registers():
    toml = tomllib.loads((ROOT / "protocol" / "registers.toml").read_text())
    by_name = {r["name"]: r for r in toml["register"]}
    assert R.DEFINITION_HASH is not None
    assert set(R.REGISTERS) == set(by_name)
    for name, reg in R.REGISTERS.items():
        t = by_name[name]
        width = 2 if t["type"] == "u32" else 1
        assert (reg.space, reg.address, reg.type, reg.count, reg.stride) == \
            (t["space"], int(t["address"]), t["type"], int(t.get("count", 1)), int(t.get("stride", width)))
    assert {m.name: int(m) for m in R.ENUMS["state"]} == toml["enums"]["state"]
    assert R.enum_value("fault", "OVERTEMP") == 0


def test_encode_decode_u32_i16_and_ranges():
    t = R.register("exposure_time_us")
    assert t.encode(15_000_000) == [15_000_000 >> 16, 15_000_000 & 0xFFFF]
    assert t.decode(t.encode(15_000_000)) == 15_000_000
    ch = R.register("manual_channel")
    assert ch.decode(ch.encode(-1)) == -1 and ch.encode(-1) == [0xFFFF]
    with pytest.raises(ValueError, match="out of range"):
        R.register("n_lights").encode(0)
    assert t.address_of(3) == t.address + 3 * t.stride
    with pytest.raises(IndexError):
        t.address_of(16)
    with pytest.raises(KeyError, match="no register named"):
        R.register("nope")
    assert R.enum_name("state", 2) == "RUNNING" and R.enum_name("state", 99) == "state?99"
