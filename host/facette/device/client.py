"""Modbus RTU client of the rig (pymodbus over any pyserial URL).

``DeviceClient(url)`` opens a serial port, the simulated device's pseudo-terminal
or ``socket://host:port`` (the QEMU board), checks the protocol definition hash,
and reads/writes registers by name (``protocol/registers.toml``). Every request is
retried on timeouts and CRC errors (a frame with a bad CRC gets no answer, so both
look like a timeout); a Modbus exception is never retried and raises
`DeviceException` with the device's own reason (`last_error`). A change of
`boot_count` between two requests means the device reset: `check_reset()` raises
`DeviceReset` once, after which the client carries on with the new boot.
"""
from __future__ import annotations

import logging
import os
import stat
import time

from facette.device import registers as R
from facette.errors import StoppedError

__all__ = ["DeviceClient", "DeviceError", "DeviceTimeout", "DeviceException", "DeviceMismatch",
           "DeviceReset", "EXCEPTION_NAMES", "FW_ERRORS"]

EXCEPTION_NAMES = {1: "ILLEGAL FUNCTION", 2: "ILLEGAL DATA ADDRESS", 3: "ILLEGAL DATA VALUE",
                   4: "SERVER DEVICE FAILURE"}
FW_ERRORS = {0: "none", -1: "function", -2: "address", -3: "value out of range",
             -4: "not allowed in this state", -5: "locked (write cal_unlock first)",
             -6: "a fault is latched (clear faults first)", -7: "invalid scan configuration",
             -8: "flash error"}
MAX_READ = 125   # registers per Modbus read (spec limit)


class DeviceError(StoppedError):
    """Something went wrong talking to the rig (exit code 1; a port that cannot be opened: 2)."""


class DeviceTimeout(DeviceError):
    """No valid answer after all retries (cable, port, wrong baud rate, device off)."""


class DeviceException(DeviceError):
    """The device answered with a Modbus exception."""

    def __init__(self, message, code, fw_error=None):
        super().__init__(message)
        self.code = code
        self.fw_error = fw_error


class DeviceMismatch(DeviceError):
    """The device speaks another protocol definition than this host."""


class DeviceReset(DeviceError):
    """The device rebooted (boot count changed) since the previous request."""

    def __init__(self, message, old_boot, new_boot):
        super().__init__(message)
        self.old_boot, self.new_boot = old_boot, new_boot


def _pty_identity(url):
    """(link, pty) identities of a pseudo-terminal path, or None for any other port.

    A pseudo-terminal's number (/dev/pts/N) is given to the next process that asks
    for one as soon as its device is gone, so a path that named our device may name
    another one a moment later (a real serial port keeps its name for its device).
    `pty` is the inode change time of /dev/pts/N (set when that pty was made, new
    for every pty given that number); `link` the symlink's own inode and change time
    when `url` is a link (a restarted simulated device makes a new one), else None.
    Either is None when it cannot be read (gone).
    """
    if "://" in url or not os.path.realpath(url).startswith("/dev/pts/"):
        return None
    try:
        st = os.lstat(url)
        link = (st.st_ino, st.st_ctime_ns) if stat.S_ISLNK(st.st_mode) else None
    except OSError:
        link = None
    try:
        pty = os.stat(url).st_ctime_ns
    except OSError:
        pty = None
    return link, pty


class DeviceClient:
    """Registers of one rig by name.

    Parameters
    ----------
    url : str, serial port ("/dev/ttyACM0"), pty path, or pyserial URL ("socket://127.0.0.1:5020")
    unit : int, Modbus unit id (1)
    baudrate : int (115200, docs/conventions.md)
    timeout_s : float, how long to wait for one answer
    retries : int, repeats of a request without a valid answer (timeouts, CRC errors)
    check_hash : bool, refuse a device whose definition hash differs from this host's
    expected_hash : int or None, the hash to expect (default: the generated module's)
    reconnect_timeout_s : float, how long to keep reopening a port that disappeared

    Attributes: ``stats`` (requests, retries, timeouts), ``boot_count``, ``identity``.
    """

    def __init__(self, url, unit=1, baudrate=115200, timeout_s=0.3, retries=5, check_hash=True,
                 expected_hash=None, reconnect_timeout_s=10.0):
        from pymodbus.client import ModbusSerialClient

        # pymodbus logs every lost frame at error level; our retries handle them.
        logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
        self.url = url
        self.unit = unit
        self.reconnect_timeout_s = float(reconnect_timeout_s)
        self.retries = int(retries)
        self.expected_hash = R.DEFINITION_HASH if expected_hash is None else int(expected_hash)
        self.stats = {"requests": 0, "retries": 0, "timeouts": 0, "exceptions": 0, "resets": 0}
        self._client = ModbusSerialClient(url, baudrate=baudrate, timeout=timeout_s, retries=0)
        self._client.set_max_no_responses(1 << 30)
        # pymodbus reopens the port by its path before a request whenever it was
        # closed: guard every open, ours and its own (see _open_port)
        self._pymodbus_connect = self._client.connect
        self._client.connect = self._open_port
        self._opened = None       # _pty_identity at the last open
        self.refused = None       # why the last open was refused (a pty that is not ours)
        self.boot_count = None
        self.identity = {}
        self.connect(check_hash=check_hash)

    # -- connection ------------------------------------------------------------
    def _open_port(self):
        """Open the port unless it is a pseudo-terminal that is no longer the one we
        opened: the same pty still, or a link the restarted device made anew. Without
        this check a client whose device was gone kept reopening /dev/pts/N and took
        the next device's pty (with its exclusive lock, so that device's own host
        could not open it: "cannot open .../device/tty")."""
        if self._client.connected:
            return True
        now = _pty_identity(self.url)
        self.refused = None
        if now is not None and self._opened is not None:
            (link0, pty0), (link, pty) = self._opened, now
            same_pty = pty is not None and pty == pty0
            new_link = link is not None and link != link0 and pty is not None
            if not (same_pty or new_link):
                self.refused = (f"{self.url} no longer leads to the device this client opened "
                                "(a pseudo-terminal's number passes to the next device that asks)")
                return False
        if not self._pymodbus_connect():
            return False
        self._opened = now
        return True

    def connect(self, check_hash=True):
        """Open the port, read the identity, check the definition hash."""
        if not self._client.connect():
            if self.refused:
                raise DeviceError(f"cannot open the port {self.url!r}: {self.refused}", exit_code=2)
            raise DeviceError(f"cannot open the port {self.url!r}",
                              hint="check the host and port, and that the device (or facette sim) listens there"
                              if str(self.url).startswith("socket://") else
                              "check the port name (ls /dev/ttyACM* /dev/ttyUSB*) and that nothing "
                              "else holds it (another facette, a terminal program)", exit_code=2)
        ident = self.read_block(["fw_version", "protocol_version", "definition_hash", "serial_number",
                                 "uptime_s", "boot_count", "reset_cause", "max_leds", "ring_len"])
        expected = self.expected_hash
        if check_hash and expected is not None and ident["definition_hash"] != expected:
            self.close()
            raise DeviceMismatch(
                f"device at {self.url} speaks protocol definition {ident['definition_hash']:#010x}, "
                f"this host expects {expected:#010x}: update the firmware or this facette so that both "
                "come from the same protocol/registers.toml")
        self.boot_count = ident["boot_count"]
        ident["reset_cause"] = R.enum_name("reset_cause", ident["reset_cause"])
        ident["url"] = self.url
        self.identity = ident
        return ident

    def close(self):
        self._client.close()

    def reopen(self):
        """Close and reopen the port (after a device reset the pty or USB port may have changed state)."""
        self._client.close()
        if not self._client.connect():
            raise DeviceError(f"cannot reopen {self.url!r}")

    def _wait_for_port(self):
        """Reopen the port until it is back (a USB device re-enumerates in ~1-2 s)."""
        deadline = time.monotonic() + self.reconnect_timeout_s
        self.stats["reopens"] = self.stats.get("reopens", 0) + 1
        while True:
            self._client.close()
            if self._client.connect():
                return True
            if self.refused and _pty_identity(self.url)[0] is None:
                # a bare /dev/pts/N never comes back for us: only a link is remade
                raise DeviceError(f"lost the device at {self.url}: {self.refused}; connect through "
                                  "the device's link name (facette-device --link) to survive restarts")
            if time.monotonic() > deadline:
                return False
            time.sleep(0.02)   # poll the port name while the device comes back

    # -- raw requests with retries -----------------------------------------------
    def _request(self, what, fn, *args, check=None, **kw):
        """Call a pymodbus request with retries; `check(rsp)` False marks an answer that
        does not fit the request (RTU has no transaction id: a late answer to an earlier
        request must not be taken for this one)."""
        from pymodbus.exceptions import ConnectionException, ModbusIOException

        last = None
        for attempt in range(self.retries + 1):
            self.stats["requests"] += 1
            if attempt:
                self.stats["retries"] += 1
            try:
                rsp = fn(*args, device_id=self.unit, **kw)
            except ModbusIOException as exc:     # timeout, or only corrupted frames arrived
                self.stats["timeouts"] += 1
                last = exc
                continue
            except ConnectionException as exc:   # the port went away (USB replug, power cycle)
                last = exc
                self.stats["timeouts"] += 1
                self._wait_for_port()
                continue
            if rsp.isError():
                code = getattr(rsp, "exception_code", None)
                self.stats["exceptions"] += 1
                return None, code, attempt
            if check is not None and not check(rsp):
                self.stats["mismatched"] = self.stats.get("mismatched", 0) + 1
                last = f"an answer that does not fit {what}"
                continue
            return rsp, None, attempt
        raise DeviceTimeout(f"no valid answer from {self.url} to {what} after {self.retries + 1} attempts "
                            f"({last}); check the cable/port and that the device is powered")

    def _raise_exception(self, what, code):
        fw = None
        try:
            rsp, c, _ = self._request("read last_error", self._client.read_input_registers,
                                      R.register("last_error").address, count=1)
            if rsp is not None:
                fw = R.register("last_error").decode(rsp.registers)
        except DeviceError:
            pass
        reason = FW_ERRORS.get(fw, f"error {fw}") if fw is not None else "unknown"
        raise DeviceException(f"device refused {what}: exception {code:02d} "
                              f"({EXCEPTION_NAMES.get(code, '?')}), reason: {reason}", code, fw)

    def read_words(self, space, address, count):
        """Read `count` 16-bit words (any count: split into legal requests)."""
        out = []
        fn = self._client.read_input_registers if space == "input" else self._client.read_holding_registers
        while count > 0:
            n = min(count, MAX_READ)
            rsp, code, _ = self._request(f"read {space} {address:#06x}+{n}", fn, address, count=n,
                                         check=lambda r, n=n: len(r.registers) == n)
            if rsp is None:
                self._raise_exception(f"read {space} {address:#06x}+{n}", code)
            out += list(rsp.registers)
            address += n
            count -= n
        return out

    def write_words(self, address, words, what="write"):
        """Write holding registers (function 16, or 06 for one word). Returns the
        attempt number that succeeded (0: first)."""
        words = [int(w) & 0xFFFF for w in words]
        if len(words) == 1:
            rsp, code, attempt = self._request(what, self._client.write_register, address, words[0])
        else:
            rsp, code, attempt = self._request(what, self._client.write_registers, address, words)
        if rsp is None:
            if attempt:  # an earlier attempt may have been executed and only its answer lost
                raise _MaybeDone(what, code)
            self._raise_exception(what, code)
        return attempt

    # -- registers by name ------------------------------------------------------
    def read(self, name, index=None):
        reg = R.register(name)
        return reg.decode(self.read_words(reg.space, reg.address_of(index), reg.words))

    def read_array(self, name):
        """All elements of an array register (one request when they are contiguous)."""
        reg = R.register(name)
        if reg.stride == reg.words:
            words = self.read_words(reg.space, reg.address, reg.count * reg.words)
            return [reg.decode(words[i * reg.words:(i + 1) * reg.words]) for i in range(reg.count)]
        return [self.read(name, i) for i in range(reg.count)]

    def read_block(self, names, index=None):
        """Read several registers of one space with as few requests as possible: {name: value}."""
        regs = [R.register(n) for n in names]
        spaces = {r.space for r in regs}
        if len(spaces) != 1:
            raise ValueError("read_block needs registers of one space")
        addrs = [r.address_of(index if r.count > 1 else None) for r in regs]
        lo = min(addrs)
        hi = max(a + r.words for a, r in zip(addrs, regs))
        words = self.read_words(regs[0].space, lo, hi - lo)
        return {r.name: r.decode(words[a - lo:a - lo + r.words]) for r, a in zip(regs, addrs)}

    def write(self, name, value, index=None):
        reg = R.register(name)
        if reg.space != "holding":
            raise ValueError(f"{name} is read-only (input register)")
        try:
            self.write_words(reg.address_of(index), reg.encode(value), what=f"write {name}={value}")
        except _MaybeDone as md:
            # A lost answer then an exception: the first write probably went through; verify.
            if self.read(name, index) != int(value):
                self._raise_exception(md.what, md.code)

    def write_array(self, name, values, start=0):
        reg = R.register(name)
        values = list(values)
        if start + len(values) > reg.count:
            raise ValueError(f"{name} has {reg.count} elements, cannot write {len(values)} from {start}")
        words = []
        for v in values:
            words += reg.encode(v)
        if reg.stride != reg.words:
            for i, v in enumerate(values):
                self.write(name, v, start + i)
            return
        try:
            self.write_words(reg.address_of(start), words, what=f"write {name}[{start}:]")
        except _MaybeDone as md:
            if self.read_array(name)[start:start + len(values)] != [int(v) for v in values]:
                self._raise_exception(md.what, md.code)

    def command(self, name, accept_states=None):
        """Write a command code by name ("ARM", "START", ...). When the answer to the
        first attempt was lost and the retry is refused, the command counts as done
        if the state is now one of `accept_states`."""
        code = R.enum_value("command", name)
        try:
            self.write_words(R.register("command").address, [code], what=f"command {name}")
        except _MaybeDone as md:
            state = self.state()
            if accept_states and state in accept_states:
                return
            self._raise_exception(md.what, md.code)

    def state(self):
        return R.enum_name("state", self.read("state"))

    def check_reset(self):
        """Raise DeviceReset (once) if the boot count changed since the last check."""
        boot = self.read("boot_count")
        if self.boot_count is not None and boot != self.boot_count:
            old, self.boot_count = self.boot_count, boot
            self.stats["resets"] += 1
            raise DeviceReset(f"the device at {self.url} reset (boot count {old} → {boot})", old, boot)
        self.boot_count = boot
        return boot

    def device_identification(self):
        """Modbus 43/14 basic identification: {"vendor", "product_code", "revision"}."""
        rsp, code, _ = self._request("read device identification", self._client.read_device_information,
                                     read_code=1, object_id=0)
        if rsp is None:
            self._raise_exception("read device identification", code)
        info = {k: (v.decode("ascii", "replace") if isinstance(v, bytes) else v)
                for k, v in rsp.information.items()}
        return {"vendor": info.get(0), "product_code": info.get(1), "revision": info.get(2)}


class _MaybeDone(Exception):
    def __init__(self, what, code):
        super().__init__(what)
        self.what, self.code = what, code
