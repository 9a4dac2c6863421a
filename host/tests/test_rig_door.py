"""The rig is the only door to the simulator: outside `facette.sim`, the package reaches the
simulator only through the `Rig` interface (`sensor`, `pixel_pitch_mm`, `save_truth`, `truth`,
`simulated_events`, `press_button`, `show_target`...), which `SimRig` answers from its
simulator and a real rig answers as "unknown". So no module but `SimRig` itself reads a
``.sim`` attribute (``rig.sim.leds``, ``rig.sim.summary()``...): the acquisition, the wizard,
the benchmarks and the command line run the same on a real rig."""
import ast
from pathlib import Path

import facette

PACKAGE = Path(facette.__file__).parent


def _sim_reads(tree):
    """(line, expression) of every ``X.sim`` read outside class SimRig's own ``self.sim``, but
    the command line's ``args.sim`` (its --sim flag, a bool)."""
    allowed = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ClassDef) and node.name == "SimRig":
            allowed.update(id(n) for n in ast.walk(node)
                           if isinstance(n, ast.Attribute) and isinstance(n.value, ast.Name)
                           and n.value.id == "self")
    return [(n.lineno, ast.unparse(n)) for n in ast.walk(tree)
            if isinstance(n, ast.Attribute) and n.attr == "sim" and id(n) not in allowed
            and not (isinstance(n.value, ast.Name) and n.value.id == "args")]


def test_only_simrig_reads_the_simulator_behind_a_rig():
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE)
        if rel.parts[0] == "sim":
            continue
        found += [f"{rel}:{line} {expr}" for line, expr in _sim_reads(ast.parse(path.read_text()))]
    assert found == [], "read the simulator through the Rig interface instead:\n" + "\n".join(found)


def test_the_check_sees_a_read_behind_the_rig():
    """The check itself: what bench/calib.py did before (rig.sim.leds) is found; SimRig's own
    self.sim and the CLI's args.sim are not."""
    code = ("class SimRig:\n    def n(self):\n        return len(self.sim.leds)\n"
            "class Other:\n    def n(self):\n        return self.sim\n"
            "def f(rig, args):\n    return args.sim and rig.sim.leds\n")
    assert _sim_reads(ast.parse(code)) == [(6, "self.sim"), (8, "rig.sim")]
