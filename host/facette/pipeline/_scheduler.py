"""A dask.distributed scheduler's address (`--scheduler`, `process --memory` and `batch`): its
form checked, and the scheduler reached within a few seconds, before any work.

Dask's own client waits 30 s for a scheduler that does not answer, then raises from deep inside
its comm layer (a 52-line traceback that read as a bug in facette); here a wrong or silent
address is bad input (exit 2) said in one line, within SCHEDULER_TIMEOUT_S.
"""
import socket
from urllib.parse import urlsplit

from facette.errors import BadInputError

__all__ = ["SCHEDULER_TIMEOUT_S", "scheduler_address", "check_scheduler", "connect_scheduler"]

SCHEDULER_TIMEOUT_S = 5.0
SCHEMES = ("tcp", "tls", "ws", "wss", "ucx")    # the transports a remote dask scheduler listens on
IN_PROCESS = "inproc://"      # a scheduler in this process (LocalCluster(processes=False)): no socket
HINT = ("check the address (dask scheduler prints it: tcp://HOST:8786), start the scheduler there, "
        "or leave --scheduler out to run here")


def scheduler_address(text):
    """(scheme, host, port) of 'tcp://host:8786', 'tls://host:8786' or 'host:8786'; BadInputError
    naming what is wrong otherwise."""
    text = str(text).strip()
    if text.startswith(IN_PROCESS) and len(text) > len(IN_PROCESS):
        return "inproc", text[len(IN_PROCESS):], None
    parts = urlsplit(text if "://" in text else f"tcp://{text}")
    try:
        port = parts.port
    except ValueError:
        port = None
    if parts.scheme not in SCHEMES or not parts.hostname or port is None or port == 0 \
            or parts.path not in ("", "/") or parts.query:
        raise BadInputError(f"--scheduler {text!r} is not a scheduler's address ({'|'.join(SCHEMES)}://HOST:PORT, "
                            "e.g. tcp://10.0.0.5:8786)", hint=HINT)
    return parts.scheme, parts.hostname, port


def check_scheduler(text, timeout=SCHEDULER_TIMEOUT_S):
    """Check that something listens at the scheduler's address (a TCP connection within `timeout`
    seconds); BadInputError saying so otherwise. Returns the address as given."""
    scheme, host, port = scheduler_address(text)
    if scheme == "inproc":
        return text                        # this process's own: the client's timeout says the rest
    try:
        with socket.create_connection((host, port), timeout=timeout):
            pass
    except socket.gaierror:
        raise BadInputError(f"--scheduler {text}: no machine is called {host!r}", hint=HINT) from None
    except OSError as exc:
        why = "did not answer" if isinstance(exc, TimeoutError) else (exc.strerror or str(exc)).lower()
        raise BadInputError(f"--scheduler {text}: nothing listens at {host}:{port} ({why}, "
                            f"{timeout:g} s)", hint=HINT) from None
    return text


def connect_scheduler(text, timeout=SCHEDULER_TIMEOUT_S):
    """A dask.distributed Client of the scheduler at `text`, given up after `timeout` seconds with
    a BadInputError (what listens there may be no dask scheduler)."""
    check_scheduler(text, timeout)
    # a deliberate lazy load: dask.distributed takes ~1 s to import
    from dask.distributed import Client
    try:
        return Client(text, timeout=f"{timeout:g}s")
    except (OSError, TimeoutError) as exc:
        raise BadInputError(f"--scheduler {text}: no dask scheduler answered within {timeout:g} s "
                            f"({type(exc).__name__})", hint=HINT) from None
