"""`facette device`: talk to a rig: identity, status, faults, registers.

    facette device --port /dev/ttyACM0 info
    facette device --port socket://127.0.0.1:5020 read state
    facette device --port /dev/pts/5 write host_watchdog_ms 10000
    facette device --port ... clear          # clear latched faults
"""
import argparse
import json

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


def run(args):
    import facette

    kw = {} if args.port == "sim" else {"check_hash": not args.no_hash_check}
    rig = facette.connect(args.port, **kw)
    try:
        dev = rig.device
        if args.action == "info":
            out = {**rig.identity, "identification": dev.device_identification()}
        elif args.action == "status":
            out = {**rig.status(), **rig.measurements()}
        elif args.action == "faults":
            out = rig.faults()
        elif args.action == "clear":
            rig.clear_faults()
            out = rig.faults()
        elif args.action == "abort":
            rig.abort()
            out = rig.status()
        elif args.action == "gains":
            out = {"gains": rig.gains()}
        elif args.action == "registers":
            out = {}
            for name, reg in R.REGISTERS.items():
                out[name] = dev.read_array(name) if reg.count > 1 else dev.read(name)
        elif args.action == "read":
            if not args.args:
                raise SystemExit("read NAME [INDEX]")
            idx = int(args.args[1]) if len(args.args) > 1 else None
            reg = R.register(args.args[0])
            out = {args.args[0]: dev.read_array(reg.name) if reg.count > 1 and idx is None
                   else dev.read(reg.name, idx)}
        else:  # write
            if len(args.args) < 2:
                raise SystemExit("write NAME VALUE [INDEX]")
            idx = int(args.args[2]) if len(args.args) > 2 else None
            dev.write(args.args[0], int(args.args[1], 0), idx)
            out = {args.args[0]: dev.read(args.args[0], idx)}
        print(json.dumps(out, indent=1, default=str))
    finally:
        rig.close()
    return 0
