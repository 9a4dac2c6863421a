"""`unchanged(*paths)`: a context manager that sha256s every file under the given paths (files or
folders) before the block and checks after it that each is still there with the same content and
that none was added: the inputs of a command are never written."""
import contextlib
import hashlib
from pathlib import Path


def tree_digest(*paths):
    """{path: sha256} of every file under `paths` (a missing path maps to None)."""
    out = {}
    for root in map(Path, paths):
        if not root.exists():
            out[str(root)] = None
        files = [root] if root.is_file() else sorted(p for p in root.rglob("*") if p.is_file())
        for f in files:
            out[str(f)] = hashlib.sha256(f.read_bytes()).hexdigest()
    return out


@contextlib.contextmanager
def unchanged(*paths):
    before = tree_digest(*paths)
    yield before
    after = tree_digest(*paths)
    changed = sorted(k for k in set(before) | set(after) if before.get(k) != after.get(k))
    assert not changed, f"inputs written: {changed[:5]}"
