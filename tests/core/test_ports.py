"""moglow_eval.core.ports: a port for a server started for a moment (the demo's app, the tests' servers) is free
and below the kernel's ephemeral range, where no outgoing connection can take it before the server binds it."""

import socket

from moglow_eval.core import ports


def test_a_free_port_is_below_the_ephemeral_range_and_can_be_bound():
    start = ports._ephemeral_start()
    picked = {ports.free_port() for _ in range(20)}
    assert all(ports.LOWEST <= p < start for p in picked), (picked, start)
    assert len(picked) > 1  # drawn at random, so that two pickers rarely meet
    with socket.socket() as s:
        s.bind(("127.0.0.1", picked.pop()))


def test_a_taken_port_is_never_given(monkeypatch):
    with socket.socket() as held:
        held.bind(("127.0.0.1", 0))
        held.listen()
        taken = held.getsockname()[1]
        draws = iter([taken, taken, taken + 1 if taken + 1 < 65536 else taken - 1])
        monkeypatch.setattr(ports.random, "randrange", lambda a, b: next(draws))
        assert ports.free_port() != taken
