"""A Dask cluster's scheduler for ``sweep --scheduler``: its address checked when parsed, and a client
of it that answers within a timeout or one ValueError (never a hang, never a Dask client's noise)."""

from __future__ import annotations

import ipaddress
import re
import socket
from typing import Any

__all__ = ["parse_scheduler", "connect"]


def parse_scheduler(text: str) -> str:
    """``--scheduler``: ``tcp://HOST:PORT`` or ``HOST:PORT`` (as ``tcp://HOST:PORT``); anything else is
    one ValueError at once, before any connection is tried."""
    t = text.strip()
    if not t:
        raise ValueError("the scheduler's address is empty (an unset variable?); give tcp://HOST:PORT")
    m = re.fullmatch(r"(?:([A-Za-z][A-Za-z0-9+.-]*)://)?(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9._-]+)(?::(\d+))?", t)
    if m is None or (m[1] or "tcp").lower() != "tcp" or m[3] is None or not 1 <= int(m[3]) <= 65535:
        why = ("not tcp://" if m is not None and (m[1] or "tcp").lower() != "tcp"
               else "no port" if m is not None and m[3] is None else "not HOST:PORT")
        raise ValueError(f"expected a Dask scheduler's address tcp://HOST:PORT (port 1 to 65535; Dask's "
                         f"default is 8786), got {text!r} ({why})")
    return f"tcp://{m[2]}:{int(m[3])}"


def _is_local(host: str) -> bool:
    """``host`` is this machine (a loopback address, or its own name)."""
    host = host.strip("[]")
    if host in ("localhost", socket.gethostname(), socket.getfqdn()):
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:  # a name
        pass
    try:
        return ipaddress.ip_address(socket.gethostbyname(host)).is_loopback
    except (OSError, ValueError):
        return False


async def _identity(address: str, timeout: float) -> dict[str, Any]:
    from distributed.comm import connect as comm_connect

    comm = await comm_connect(address, timeout=timeout)  # retries until the timeout
    try:
        await comm.write({"op": "identity", "reply": True})
        return await comm.read()
    finally:
        comm.abort()


def _check_scheduler(address: str, timeout: float) -> None:
    """ValueError unless a Dask scheduler answers at ``address`` within ``timeout`` s: at once when
    nothing listens on this machine (no scheduler can start there meanwhile but the user's own);
    without building a Dask client, whose failed start leaves noise behind."""
    import asyncio

    host, port = address[len("tcp://"):].rsplit(":", 1)
    if _is_local(host):
        try:
            socket.create_connection((host.strip("[]"), int(port)), timeout=min(timeout, 2.0)).close()
        except ConnectionRefusedError:
            raise ValueError(f"--scheduler {address}: nothing listens there (start one with 'dask scheduler "
                             f"--port {port}')") from None
        except OSError:
            pass  # left to the full attempt below, which says what happened
    try:
        reply = asyncio.run(asyncio.wait_for(_identity(address, timeout), timeout + 1.0))
    except Exception as exc:  # OSError (refused, timeout), garbage from a peer that is not Dask
        detail = " ".join(str(exc).split()) or type(exc).__name__
        raise ValueError(f"--scheduler {address}: no Dask scheduler answered within {timeout:g} s "
                         f"({detail[:200]})") from None
    if not isinstance(reply, dict) or reply.get("type") != "Scheduler":
        raise ValueError(f"--scheduler {address}: something answered there, but not a Dask scheduler")


def connect(address: str, timeout: float) -> Any:
    """A Dask client of the scheduler at ``address`` (:func:`parse_scheduler`'s form) with at least one
    worker, or ValueError within ``timeout`` seconds per step (never a hang)."""
    from distributed import Client

    _check_scheduler(address, timeout)
    try:
        client = Client(address, timeout=f"{timeout}s", set_as_default=False)
    except Exception as exc:  # the scheduler went away since it answered
        raise ValueError(f"--scheduler {address}: no Dask scheduler answered within {timeout:g} s "
                         f"({' '.join(str(exc).split()) or type(exc).__name__})") from None
    try:
        client.wait_for_workers(1, timeout=timeout)
    except Exception:
        client.close()
        raise ValueError(f"--scheduler {address}: the scheduler has no worker (start some with "
                         f"'dask worker {address}')") from None
    return client
