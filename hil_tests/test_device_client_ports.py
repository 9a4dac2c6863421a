"""A pseudo-terminal's number passes to the next device that asks for one: a client
whose device is gone must not open the pty that number now names."""
from __future__ import annotations

import fcntl
import os

import pytest

from posix_device import start_posix_device, stop_posix_device
from facette.device import DeviceClient, DeviceError


def _take_pty_number(path, tries=50):
    """Open new ptys until one is /dev/pts/N == path (its device is gone, so the
    number is free unless another process took it first); returns the fds held."""
    held = []
    for _ in range(tries):
        master, slave = os.openpty()
        held += [master, slave]
        if os.ttyname(slave) == path:
            break
    return held


def test_a_client_whose_device_is_gone_never_opens_the_pty_its_number_now_names(tmp_path):
    dev = start_posix_device(tmp_path)
    try:
        client = DeviceClient(dev.port, reconnect_timeout_s=2.0)
        # the same pty, closed and reopened (what pymodbus does after an error): allowed
        client._client.close()
        assert client._client.connect()
    finally:
        stop_posix_device(dev)
    client._client.close()
    held = _take_pty_number(dev.port)
    try:
        # whoever holds /dev/pts/N now (this test, another process, or nobody), it is
        # not our device: the client refuses to open it, and leaves it unlocked
        assert not client._client.connect()
        assert "no longer leads to the device" in client.refused
        if os.path.exists(dev.port):
            fd = os.open(dev.port, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)   # nobody else holds it
            finally:
                os.close(fd)
        with pytest.raises(DeviceError, match="link name"):
            client.read_words("input", 0, 1)
    finally:
        for fd in held:
            os.close(fd)
        client.close()


def test_a_client_through_a_link_reopens_the_restarted_device(tmp_path):
    from facette.sim.device_process import SimulatedDevice

    dev = SimulatedDevice(side=False, workdir=tmp_path / "dev", link=True)
    try:
        client = DeviceClient(dev.port)
        boot = client.boot_count
        dev.restart()                       # a new pty behind a new link of the same name
        assert client.read_words("input", 0, 1)   # reopened through the link
        client.connect(check_hash=True)
        assert client.boot_count == boot + 1
        client.close()
    finally:
        dev.close()
