"""The page of every error and note facette prints, collected from the source.

Errors: each `raise` of a `facette.errors` kind (any class deriving from `FacetteError`, found by
reading the class definitions) with its message and its `hint=`; notes: the strings appended to a
`notes` list or passed to a `note(...)` call. A message built at run time shows its parts as
`{...}` (the file, the light, the value). Grouped by the part of facette that says it, so a new
`raise BadInputError(..., hint=...)` appears at the next `make docs`.
"""
import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "host" / "facette"
ROOTS = {"FacetteError"}
AREAS = {   # subpackage -> what a reader knows it as
    "cli": "the command line", "pipeline": "processing (`facette process`, `facette batch`)",
    "scan": "scanning (`facette scan`)", "wizard": "the calibration wizard", "calib": "calibration profiles and checks",
    "device": "the device link", "camera": "the camera and RAW files", "io": "reading and writing files",
    "fit": "the BRDF and normal fits", "recon": "photometric stereo and integration", "hdr": "the HDR merge",
    "sim": "the simulated rig", "reflect": "reflectance samples", "brdf": "BRDF models", "bench": "benchmarks",
    "methods": "the method table", "errors": "errors", "": "the package",
}


def _modules(package):
    return sorted(p for p in package.rglob("*.py") if "__pycache__" not in p.parts)


def facette_error_kinds(trees):
    """Names of every class deriving (through any chain) from FacetteError."""
    bases = {}
    for tree in trees.values():
        for node in ast.walk(tree):
            if isinstance(node, ast.ClassDef):
                bases[node.name] = {b.id if isinstance(b, ast.Name) else getattr(b, "attr", "") for b in node.bases}
    kinds, grew = set(ROOTS), True
    while grew:
        new = {name for name, b in bases.items() if b & kinds} - kinds
        kinds |= new
        grew = bool(new)
    return kinds


def text_of(node):
    """A string expression as a reader sees it: literals kept, run-time parts as {...}."""
    if isinstance(node, ast.Constant) and isinstance(node.value, str):
        return node.value
    if isinstance(node, ast.JoinedStr):
        return "".join(v.value if isinstance(v, ast.Constant) else "{...}" for v in node.values)
    if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.Mod)):
        left = text_of(node.left)
        right = text_of(node.right) if isinstance(node.op, ast.Add) else ""
        if left is None and right is None:
            return None
        return (left or "{...}") + (right if right is not None else "{...}")
    if isinstance(node, ast.IfExp):
        a, b = text_of(node.body), text_of(node.orelse)
        return a if a is not None else b
    if isinstance(node, ast.Call) and getattr(node.func, "attr", "") == "join" and node.args:
        return "{...}"
    return None


def _name(func):
    return func.id if isinstance(func, ast.Name) else getattr(func, "attr", "")


def collect(package=PACKAGE):
    """{area: {"errors": [(kind, message, hint)], "notes": [text]}} from the package's source."""
    package = Path(package)
    trees = {p: ast.parse(p.read_text(encoding="utf-8")) for p in _modules(package)}
    kinds = facette_error_kinds(trees)
    found = {}
    for path, tree in trees.items():
        rel = path.relative_to(package).parts
        area = rel[0] if len(rel) > 1 else ""
        bucket = found.setdefault(area, {"errors": [], "notes": []})
        for node in ast.walk(tree):
            if isinstance(node, ast.Raise) and isinstance(node.exc, ast.Call) and _name(node.exc.func) in kinds:
                call = node.exc
                message = text_of(call.args[0]) if call.args else None
                hint = next((text_of(k.value) for k in call.keywords if k.arg == "hint"), None)
                if message:
                    bucket["errors"].append((_name(call.func), message, hint or ""))
            elif isinstance(node, ast.Call) and node.args and (
                    _name(node.func) in ("note", "_note", "add_note")
                    or (_name(node.func) == "append" and getattr(node.func.value, "id", "").endswith("notes"))):
                text = text_of(node.args[0])
                if text and len(text.strip(" {}.")) > 3:
                    bucket["notes"].append(text)
    return found


def _cell(text):
    return " ".join(text.split()).replace("|", "\\|").replace("<", "&lt;").replace("*", "\\*").replace("_", "\\_")


def page_section():
    out = []
    for area, got in sorted(collect().items(), key=lambda kv: (kv[0] == "", kv[0])):
        errors = sorted(set(got["errors"]), key=lambda e: e[1].lower())
        notes = sorted(set(got["notes"]), key=str.lower)
        if not errors and not notes:
            continue
        out += ["", f"### {AREAS.get(area, area)}", ""]
        if errors:
            out += ["| kind | what facette says | what to do |", "| --- | --- | --- |"]
            out += [f"| `{k}` | {_cell(m)} | {_cell(h)} |" for k, m, h in errors]
        if notes:
            out += ["", "Notes:", ""] + [f"- {_cell(n)}" for n in notes]
    return "\n".join(out) + "\n"


if __name__ == "__main__":
    print(page_section())
