"""No state in module globals between calls in `pipeline`, `scan` and `cli`: a module-level dict,
list or set that some code of the module changes (item, append, update, `global` rebinding...)
is a result parked for someone else to pick up; it should be returned and passed on instead."""
import ast
from pathlib import Path

import facette

PACKAGE = Path(facette.__file__).parent
CHECKED = ("pipeline", "scan", "cli")
# (scan/hdr.py's `_HELD`, the merged lights parked by file path, was the last one: gone with t27b's
# change; tests/scan/test_hdr.py checks facette.scan more strictly: no module-level container at all)
MUTATORS = {"append", "extend", "insert", "add", "update", "setdefault", "pop", "popitem", "clear",
            "remove", "discard", "__setitem__", "__delitem__", "sort", "reverse",
            "intersection_update", "difference_update", "symmetric_difference_update"}
CONTAINER_CALLS = {"dict", "list", "set", "defaultdict", "OrderedDict", "Counter", "deque"}


def _container(value):
    if isinstance(value, (ast.Dict, ast.List, ast.Set, ast.DictComp, ast.ListComp, ast.SetComp)):
        return True
    if isinstance(value, ast.Call):
        f = value.func
        name = f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else None
        return name in CONTAINER_CALLS
    return False


def module_containers(tree):
    """Names bound at module level to a mutable container."""
    names = set()
    for node in tree.body:
        targets = node.targets if isinstance(node, ast.Assign) else \
            [node.target] if isinstance(node, ast.AnnAssign) and node.value is not None else []
        if targets and _container(node.value):
            names.update(t.id for t in targets if isinstance(t, ast.Name))
    return names


def mutated(tree, names):
    """The names of `names` that some statement of the module changes."""
    out = set()

    def base(node):
        while isinstance(node, (ast.Subscript, ast.Attribute)):
            node = node.value
        return node.id if isinstance(node, ast.Name) else None

    for node in ast.walk(tree):
        if isinstance(node, (ast.Assign, ast.AugAssign, ast.AnnAssign, ast.Delete)):
            targets = node.targets if isinstance(node, (ast.Assign, ast.Delete)) else [node.target]
            for t in targets:
                if isinstance(t, ast.Subscript) or (isinstance(node, ast.AugAssign) and isinstance(t, ast.Name)):
                    out.add(base(t))
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) \
                and node.func.attr in MUTATORS:
            out.add(base(node.func.value) if isinstance(node.func.value, ast.Name) else None)
        elif isinstance(node, ast.Global):
            out.update(node.names)
    return out & names


def offenders(root=PACKAGE, subpackages=CHECKED):
    found = set()
    for sub in subpackages:
        for path in sorted((root / sub).rglob("*.py")):
            tree = ast.parse(path.read_text())
            rel = path.relative_to(root).as_posix()
            found.update((rel, name) for name in mutated(tree, module_containers(tree)))
    return found


def test_no_module_level_state_in_pipeline_scan_cli():
    assert offenders() == set()


def test_the_check_sees_state_it_should_refuse(tmp_path):
    (tmp_path / "p").mkdir()
    (tmp_path / "p" / "m.py").write_text(
        "HELD = {}\nSEEN = []\nCONST = {'a': 1}\nTOTAL = set()\nN = dict()\n"
        "def park(k, v):\n    HELD[k] = v\n"
        "def note(x):\n    SEEN.append(x)\n"
        "def read(k):\n    return CONST[k]\n"
        "def reset():\n    global N\n    N = {}\n")
    assert offenders(tmp_path, ("p",)) == {("p/m.py", "HELD"), ("p/m.py", "SEEN"), ("p/m.py", "N")}
