"""facette.sim: the simulated rig (docs/ARCHITECTURE.md, layer 5).

`SimulatedRig` starts the firmware's posix build (``build/posix/facette-device``)
and a rig simulator on its side channel: a virtual object (`scene`), LEDs with
errors (`lights`), rendering (`render`), and a Bayer camera (`sensor`, `dng`)
writing DNG files into a folder. ``facette.connect("sim")`` uses it.
"""
from facette.sim.rig import Faults, RigSimulator, SimCamera
from facette.sim.scene import SCENES, Scene, make_scene
from facette.sim.simrig import SimulatedRig

__all__ = ["SimulatedRig", "RigSimulator", "SimCamera", "Faults", "Scene", "make_scene", "SCENES"]
