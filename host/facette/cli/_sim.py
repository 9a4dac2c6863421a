"""`facette sim`: start a simulated rig and keep it running.

The first line of standard output is ``port: <path>`` (the Modbus pseudo-terminal);
then ``camera: <folder>`` (where its DNG files appear). Commands on standard input,
one per line: ``button`` (press and release), ``ntc <°C>``, ``reset``, ``biterr <p>``,
``led_fault <ch> open|short|ok``, ``status``, ``quit``. ``quit`` or Ctrl-C stops it;
with standard input closed (``< /dev/null``) it runs until killed.
"""
import argparse
import os
import sys
import threading
import time

DEAD_CHECKS = 4          # the device's process seen ended this many times in a row (0.5 s apart):
                         # a restart (reset) takes far less

from facette.cli._process import _number
from facette.cli._scan import SIM_RAW_SIZE, SIM_RAW_SIZE_TEXT, _positive, _shape


def register(sub):
    p = sub.add_parser("sim", help="start the simulated rig", description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scene", default="plaque_sphere", help="plaque_sphere, plaque, sphere or plane")
    p.add_argument("--raw-size", type=_shape, default=SIM_RAW_SIZE, metavar="WxH",
                   help=f"RAW size (default {SIM_RAW_SIZE_TEXT})")
    p.add_argument("--near", action="store_true", help="LEDs as near point sources at 1.5 m")
    p.add_argument("--brdf", default="mask",
                   help="material: mask, bust or lambert (facette.sim.scene.BRDF_PRESETS)")
    p.add_argument("--faults", default="", help="e.g. 'biterr=1e-3,reset_at_shot=5,miss_sync_shots=3'")
    p.add_argument("--speed", type=_positive(float), default=1.0, help="device clock, × real time (default 1)")
    p.add_argument("--workdir", help="keep the camera folder and flash here (default: temporary)")
    p.add_argument("--seed", type=_number(int, 0, None, what="--seed"), default=0, help="noise seed, >= 0")
    return p


def _died(sim):
    """The lines that say the device's firmware process ended, and what to do."""
    code = sim.device.proc.poll()
    log = sim.device.workdir / "device.log"
    return (f"facette sim: the simulated device's firmware process ended (exit code {code}); the rig is "
            f"gone (its log: {log})\n  start facette sim again")


def _watch(sim, stopping):
    """Stop the whole command, saying why, when the device's process ends for good."""
    dead = 0
    while not stopping.wait(0.5):
        dead = dead + 1 if not sim.device.alive() else 0
        if dead >= DEAD_CHECKS:
            print(_died(sim), file=sys.stderr, flush=True)
            try:
                sim.close()
            finally:
                os._exit(1)       # the main thread is blocked reading standard input


def run(args):
    from facette.sim import SimulatedRig

    sim = SimulatedRig(scene=args.scene, raw_shape=args.raw_size, near=args.near, brdf=args.brdf,
                       faults=args.faults or None, speed=args.speed, workdir=args.workdir, seed=args.seed,
                       max_unclaimed=None)
    stopping = threading.Event()
    threading.Thread(target=_watch, args=(sim, stopping), daemon=True).start()
    try:
        print(f"port: {sim.port}", flush=True)
        print(f"camera: {sim.camera_dir}", flush=True)
        print("commands: button | ntc <degC> | reset | biterr <p> | led_fault <ch> open|short|ok | status | quit",
              flush=True)
        for line in sys.stdin:
            cmd = line.split()
            if not cmd:
                continue
            if cmd[0] == "quit":
                break
            if cmd[0] == "button":
                sim.simulator.button(True)
                time.sleep(0.1 / max(args.speed, 1e-3) + 0.05)   # held ~100 ms of device time
                sim.simulator.button(False)
            elif cmd[0] == "ntc" and len(cmd) == 2:
                sim.set_temperature(float(cmd[1]))
            elif cmd[0] == "status":
                print(sim.summary(), flush=True)
            elif cmd[0] in ("reset", "biterr", "led_fault", "supply", "miss_sync"):
                sim.simulator.send(" ".join(cmd))
            else:
                print(f"unknown command {line.strip()!r}", file=sys.stderr, flush=True)
        else:
            # standard input closed: serve until killed (or the device exits)
            while not stopping.wait(0.5):
                pass
    finally:
        stopping.set()
        sim.close()
    return 0
