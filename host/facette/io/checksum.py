"""File checksums (sha256), read in 1 MiB blocks so a 25 MB RAW never sits whole in memory."""
import hashlib

__all__ = ["sha256_file"]


def sha256_file(path):
    """Hex sha256 of the file at `path`."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()
