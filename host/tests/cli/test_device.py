"""`facette device` against the real firmware core over a pty: every action's happy path, and
bad names, values, indexes and ports in words with exit 2 (a device refusal: exit 1)."""
import json

import pytest

from facette.cli.main import main


@pytest.fixture(scope="module")
def port(sim_device):
    return sim_device.port


def dev_cli(capsys, port, *args):
    try:
        code = main(["device", "--port", port, *[str(a) for a in args]])
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


@pytest.mark.parametrize("action, key", [("info", "identification"), ("status", "state"),
                                         ("faults", "latched"), ("clear", "latched"),
                                         ("gains", "gains"), ("registers", "max_current_mA")])
def test_actions(capsys, port, action, key):
    code, out, err = dev_cli(capsys, port, action)
    assert code == 0, err
    assert key in json.loads(out)


def test_read_and_write_by_name_and_index(capsys, port):
    assert dev_cli(capsys, port, "write", "gap_us", "0x3e8")[0] == 0
    code, out, _ = dev_cli(capsys, port, "read", "gap_us")
    assert code == 0 and json.loads(out) == {"gap_us": 1000}
    assert dev_cli(capsys, port, "write", "light_current_mA", 450, 2)[0] == 0
    code, out, _ = dev_cli(capsys, port, "read", "light_current_mA", 2)
    assert json.loads(out) == {"light_current_mA": 450}
    code, out, _ = dev_cli(capsys, port, "read", "light_current_mA")
    assert len(json.loads(out)["light_current_mA"]) == 16
    code, out, _ = dev_cli(capsys, port, "status")
    assert json.loads(out)["last_error"].endswith(")")          # the code and its words


@pytest.mark.parametrize("args, code, words", [
    (["read", "max_curent_mA"], 2, "no register named 'max_curent_mA'; did you mean max_current_mA"),
    (["read", "temperature"], 2, "no register named 'temperature'"),
    (["write", "n_lights", "abc"], 2, "value for n_lights 'abc' is not a whole number"),
    (["write", "n_lights", "99"], 2, "n_lights = 99 is out of range [1, 16]"),
    (["write", "state", "1"], 2, "state is read-only"),
    (["write", "light_current_mA", "400"], 2, "is an array of 16: write light_current_mA VALUE INDEX"),
    (["read", "light_current_mA", "16"], 2, "light_current_mA has elements 0..15; index 16"),
    (["read", "gap_us", "1"], 2, "gap_us is not an array"),
    (["read"], 2, "read NAME [INDEX]"),
    (["write", "gap_us"], 2, "write NAME VALUE [INDEX]"),
    (["info", "extra"], 2, "info takes no arguments"),
    (["abort"], 1, "nothing to abort: the device is"),
    (["write", "cal_gain", "12000", "0"], 1, "locked (write cal_unlock first)"),
])
def test_mistakes_are_said_in_words(capsys, port, args, code, words):
    got, out, err = dev_cli(capsys, port, *args)
    assert got == code and words in err, err
    assert "Traceback" not in err and len(err.splitlines()) <= 2


def test_a_bad_port(capsys, tmp_path):
    got, out, err = dev_cli(capsys, str(tmp_path / "ttyNONE"), "info")
    assert got == 2 and "cannot open the port" in err and "check the port name" in err, err


def test_a_current_above_the_device_limit_is_said_when_written(capsys, port):
    code, out, err = dev_cli(capsys, port, "write", "manual_current_mA", "1500")
    assert code == 0
    said = json.loads(out)
    assert said["manual_current_mA"] == 1500                  # what the register holds
    assert "max_current_mA = 1000 mA" in said["note"] and "max_current_mA = 1000 mA" in err
    code, out, err = dev_cli(capsys, port, "write", "manual_current_mA", "800")
    assert code == 0 and "note" not in json.loads(out) and "note" not in err
