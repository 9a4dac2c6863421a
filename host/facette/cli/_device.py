"""`facette device`: talk to a rig: identity, status, faults, registers.

    facette device --port /dev/ttyACM0 info
    facette device --port socket://127.0.0.1:5020 read state
    facette device --port /dev/pts/5 write host_watchdog_ms 10000
    facette device --port ... clear          # clear latched faults
"""
import argparse
import json
import sys

from facette.device import registers as R


def register(sub):
    p = sub.add_parser("device", help="device info, faults and registers", description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--port", help="serial port, pty, or socket://host:port (or 'sim' for a simulated rig)",
                   required=True)
    p.add_argument("--no-hash-check", action="store_true", help="talk to a device of another definition")
    p.add_argument("action", choices=("info", "status", "faults", "clear", "abort", "registers", "read",
                                      "write", "gains"))
    p.add_argument("args", nargs="*", help="read NAME [INDEX] | write NAME VALUE [INDEX]")
    return p


def _register(dev, name, port="PORT"):
    """The register called `name`, or a BadInputError listing the closest names."""
    import difflib

    from facette.errors import BadInputError

    if name in R.REGISTERS:
        return R.REGISTERS[name]
    names = sorted(R.REGISTERS)
    close = difflib.get_close_matches(name, names, n=5, cutoff=0.5) or \
        [n for n in names if name.lower() in n.lower()][:5]
    raise BadInputError(f"no register named {name!r}"
                        + (f"; did you mean {', '.join(close)}?" if close else ""),
                        hint=f"facette device --port {port} registers lists them all with their values")


def _number(text, what):
    from facette.errors import BadInputError

    try:
        return int(text, 0)
    except ValueError:
        raise BadInputError(f"{what} {text!r} is not a whole number",
                            hint="write it in decimal (1000) or hex (0x3e8)") from None


def _index(dev, reg, args, at):
    """The optional INDEX argument at position `at` (checked against the register's count)."""
    from facette.errors import BadInputError

    if len(args) <= at:
        return None
    idx = _number(args[at], f"index of {reg.name}")
    if reg.count == 1:
        raise BadInputError(f"{reg.name} is not an array: give no index")
    if not 0 <= idx < reg.count:
        raise BadInputError(f"{reg.name} has elements 0..{reg.count - 1}; index {idx} is not one of them")
    return idx


def _check_write(reg, value):
    from facette.errors import BadInputError

    if reg.space != "holding":
        raise BadInputError(f"{reg.name} is read-only (a measurement or status the device reports)")
    try:
        reg.encode(value)
    except ValueError as exc:
        raise BadInputError(str(exc), hint=f"{reg.name} takes {reg.minimum}..{reg.maximum}"
                            + (f" {reg.unit}" if reg.unit else "")) from None


def _clamp_note(dev, reg, value):
    """The line saying that a current written above the device's max_current_mA is driven at
    that limit (the register keeps the value written), or None."""
    if reg.space != "holding" or reg.unit != "mA" or "current" not in reg.name or reg.name == "max_current_mA":
        return None
    limit = dev.read("max_current_mA")
    if value <= limit:
        return None
    return (f"{reg.name} holds {value} mA but the device drives at most max_current_mA = {limit} mA: "
            "the rest is not driven (raise max_current_mA, up to 1500, to drive more)")


def _command(rig, action):
    """clear / abort, refused in words when the device's state does not allow it."""
    from facette.errors import BadInputError

    if action == "abort":
        state = rig.device.state()
        if state not in ("ARMED", "RUNNING", "PAUSED"):
            raise BadInputError(f"nothing to abort: the device is {state} (no scan is armed or running)",
                                exit_code=1)
        rig.abort()
    else:
        rig.clear_faults()


def run(args):
    import facette

    if args.action == "read" and not args.args:
        raise SystemExit(f"read NAME [INDEX]: say which register (facette device --port {args.port} registers "
                         "lists them)")
    if args.action == "write" and len(args.args) < 2:
        raise SystemExit("write NAME VALUE [INDEX]")
    if args.action not in ("read", "write") and args.args:
        raise SystemExit(f"{args.action} takes no arguments; got {' '.join(args.args)}")
    if args.action == "write":
        _number(args.args[1], f"value for {args.args[0]}")   # before the port is opened
    kw = {} if args.port == "sim" else {"check_hash": not args.no_hash_check}
    rig = facette.connect(args.port, **kw)
    try:
        dev = rig.device
        if args.action == "info":
            out = {**rig.identity, "identification": dev.device_identification()}
        elif args.action == "status":
            out = {**rig.status(), **rig.measurements()}
            out["last_error"] = f"{out['last_error']} ({rig.last_error()})"
        elif args.action == "faults":
            out = rig.faults()
        elif args.action in ("clear", "abort"):
            _command(rig, args.action)
            out = rig.faults() if args.action == "clear" else rig.status()
        elif args.action == "gains":
            out = {"gains": rig.gains()}
        elif args.action == "registers":
            out = {}
            for name, reg in R.REGISTERS.items():
                out[name] = dev.read_array(name) if reg.count > 1 else dev.read(name)
        elif args.action == "read":
            reg = _register(dev, args.args[0], args.port)
            idx = _index(dev, reg, args.args, 1)
            out = {reg.name: dev.read_array(reg.name) if reg.count > 1 and idx is None
                   else dev.read(reg.name, idx)}
        else:  # write
            reg = _register(dev, args.args[0], args.port)
            value = _number(args.args[1], f"value for {reg.name}")
            idx = _index(dev, reg, args.args, 2)
            if reg.count > 1 and idx is None:
                raise SystemExit(f"{reg.name} is an array of {reg.count}: write {reg.name} VALUE INDEX")
            _check_write(reg, value)
            dev.write(reg.name, value, idx)
            out = {reg.name: dev.read(reg.name, idx)}
            note = _clamp_note(dev, reg, value)
            if note:
                out["note"] = note
                print(f"facette device: note: {note}", file=sys.stderr)
        print(json.dumps(out, indent=1, default=str))
    finally:
        rig.close()
    return 0
