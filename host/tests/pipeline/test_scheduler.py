"""pipeline._scheduler: a scheduler's address checked by its form, and reached within seconds."""
import socket

import pytest

from facette.errors import BadInputError
from facette.pipeline._scheduler import check_scheduler, scheduler_address


@pytest.mark.parametrize("text, want", [("tcp://10.0.0.5:8786", ("tcp", "10.0.0.5", 8786)),
                                        ("host:8786", ("tcp", "host", 8786)),
                                        ("tls://h.example:9000", ("tls", "h.example", 9000)),
                                        ("inproc://10.0.0.5/123/1", ("inproc", "10.0.0.5/123/1", None))])
def test_addresses_a_scheduler_listens_at(text, want):
    assert scheduler_address(text) == want


@pytest.mark.parametrize("text", ["http://host:8786", "tcp://host", "tcp://:8786", "tcp://host:99999",
                                  "tcp://host:0", "tcp://host:8786/path", "", "inproc://"])
def test_what_is_no_address_is_said_with_the_form_to_give(text):
    with pytest.raises(BadInputError, match="is not a scheduler's address.*tcp://10.0.0.5:8786"):
        scheduler_address(text)


def test_nothing_listening_is_bad_input_and_a_listener_passes():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
        with pytest.raises(BadInputError, match=f"nothing listens at 127.0.0.1:{port}") as exc:
            check_scheduler(f"tcp://127.0.0.1:{port}", timeout=2)
        assert "leave --scheduler out" in exc.value.hint
        s.listen()
        assert check_scheduler(f"tcp://127.0.0.1:{port}", timeout=2) == f"tcp://127.0.0.1:{port}"
    with pytest.raises(BadInputError, match="no machine is called"):
        check_scheduler("tcp://no-such-host.invalid:8786", timeout=2)
