"""Whether a sweep's `--address` names a Ray cluster that answers, asked before Ray is imported.

Ray's `ray.init(address="HOST:PORT")` waits for a cluster's GCS that is not there for many minutes (a
mistyped address hung `--check` for over ten), so an address of a host and port is first tried with a
plain TCP connection that gives up after a few seconds. `auto` and `local` are Ray's to resolve: they
name no host to try.
"""

from __future__ import annotations

import socket

CONNECT_TIMEOUT_S = 5.0
RAY_CLIENT = "ray://"
RESOLVED_BY_RAY = ("auto", "local")


def address_problem(address: str) -> str | None:
    """Why `address` names no reachable cluster (None: it answers, or Ray resolves it)."""
    if address in RESOLVED_BY_RAY:
        return None
    hostport = address.removeprefix(RAY_CLIENT)
    host, _, port = hostport.rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        return "must be auto, HOST:PORT or ray://HOST:PORT (what `ray start --head` prints)"
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=CONNECT_TIMEOUT_S):
            return None
    except socket.gaierror:
        return f"{host} is not a known host (a typo?), or leave --address out for a local Ray"
    except TimeoutError:
        why = f"nothing answered at {hostport} within {CONNECT_TIMEOUT_S:.0f} s"
    except OSError as err:
        why = f"nothing answers at {hostport} ({err.strerror or type(err).__name__})"
    return f"{why}: start the cluster first (`ray start --head` prints its address), or leave --address out"
