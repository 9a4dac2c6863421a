"""Register map adapter: the generated module and the TOML agree; encode/decode."""
import pytest

from facette.device.regmap import _from_toml, load_map
from facette.sim.device_process import REPO_ROOT


def test_generated_module_and_toml_describe_the_same_registers():
    gen = load_map()
    toml = _from_toml(REPO_ROOT / "protocol" / "registers.toml")
    assert gen.definition_hash is not None
    assert set(gen.registers) == set(toml.registers)
    for name, reg in gen.registers.items():
        t = toml[name]
        assert (reg.space, reg.address, reg.type, reg.count, reg.stride) == \
            (t.space, t.address, t.type, t.count, t.stride)
    assert gen.enums["state"] == toml.enums["state"]
    assert gen.enums["fault"]["OVERTEMP"] == 0


def test_encode_decode_u32_i16_and_ranges():
    m = load_map()
    t = m["exposure_time_us"]
    assert t.encode(15_000_000) == [15_000_000 >> 16, 15_000_000 & 0xFFFF]
    assert t.decode(t.encode(15_000_000)) == 15_000_000
    ch = m["manual_channel"]
    assert ch.decode(ch.encode(-1)) == -1 and ch.encode(-1) == [0xFFFF]
    with pytest.raises(ValueError, match="out of range"):
        m["n_lights"].encode(0)
    assert t.address_of(3) == t.address + 3 * t.stride
    with pytest.raises(IndexError):
        t.address_of(16)
    with pytest.raises(KeyError, match="no register named"):
        m["nope"]
