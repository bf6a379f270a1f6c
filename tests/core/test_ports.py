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
    draw = ports.random.randrange
    calls = []

    def taken_twice(a, b):  # the held port drawn first and second, then the picker's own draws
        calls.append(a)
        return taken if len(calls) <= 2 else draw(a, b)

    with socket.socket() as held:
        held.bind(("127.0.0.1", 0))
        held.listen()
        taken = held.getsockname()[1]
        monkeypatch.setattr(ports.random, "randrange", taken_twice)
        port = ports.free_port()
    assert port != taken and len(calls) >= 3
    assert ports.LOWEST <= port < ports._ephemeral_start()


def test_a_port_is_given_once_in_a_process(monkeypatch):
    """A caller that takes an app's port and its proxy's before starting either gets two ports, even where the
    draw repeats itself."""
    draw = ports.random.randrange
    first = ports.free_port()
    repeats = iter([first, first])
    monkeypatch.setattr(ports.random, "randrange", lambda a, b: next(repeats, None) or draw(a, b))
    second = ports.free_port()
    assert second != first
