"""Ports for the servers this project starts on loopback for a moment: the demo's app, and the tests' and
benchmarks' apps, proxies, PostgreSQL and Dask schedulers.

A port the kernel hands out for `bind(0)` is one of its ephemeral ports, which it also gives every outgoing
connection (a client to PostgreSQL, chromedriver, a crowd): between taking such a port and the server binding it,
another process's connection can take it, and the server fails with "address already in use" (a proxy in the test
suite did so once). A port below the ephemeral range is never given to an outgoing connection, so only another
such pick could take it: drawn at random from thousands, and checked free, that is rare. Within one process a
port is handed out once: a caller that takes two ports before it starts either server (an app and its proxy) would
otherwise be given the same port in about one pair of draws in twenty thousand.
"""

import random
import socket
from pathlib import Path

LOWEST = 10_000  # below this, ports that services on a developer's machine tend to use
_GIVEN: set[int] = set()  # the ports this process has handed out (a free port is not yet a bound one)


def _ephemeral_start() -> int:
    try:
        return int(Path("/proc/sys/net/ipv4/ip_local_port_range").read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return 32_768  # Linux's default


def free_port() -> int:
    """A port on 127.0.0.1 that nothing listens on, below the kernel's ephemeral range, not handed out before in this
    process."""
    top = _ephemeral_start()
    for _ in range(200):
        port = random.randrange(LOWEST, top)
        if port in _GIVEN:
            continue
        with socket.socket() as s:
            try:
                s.bind(("127.0.0.1", port))
            except OSError:
                continue
        _GIVEN.add(port)
        return port
    with socket.socket() as s:  # a machine whose low ports are all taken: the kernel's pick, as before
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]
