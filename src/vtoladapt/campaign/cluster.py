"""Where a campaign's runs go: the local Dask cluster, a given scheduler, and the flags naming them.

The local cluster's scheduler, workers and status page listen on ``127.0.0.1`` only (another
address with ``--listen``, checked here to be an address of this machine before anything
starts); connecting to a given scheduler gives up after :data:`SCHEDULER_CONNECT_TIMEOUT_S` with
a one-line error. The local cluster's worker processes never see Ctrl-C: the terminal sends
SIGINT to the whole process group, and a worker that took it printed its own 30-line traceback
before the command's one-line "interrupted"; the command shuts the cluster down itself.
"""
from __future__ import annotations

import ipaddress
import re
import signal
import socket
import threading
from typing import Optional

from ..config import ConfigError

SCHEDULER_CONNECT_TIMEOUT_S = 5.0
"""How long ``--scheduler ADDRESS`` waits for the scheduler to answer."""
LOOPBACK = "127.0.0.1"
SCHEDULER_SCHEMES = ("tcp://", "tls://", "ucx://", "inproc://", "ws://", "wss://")
HOST_NAME_PATTERN = r"[A-Za-z0-9]([A-Za-z0-9.-]{0,251}[A-Za-z0-9])?"
LISTEN_ALLOWED = "an IPv4 address or host name of this machine (127.0.0.1, 0.0.0.0 for every interface)"


def check_scheduler(address: str) -> None:
    """A one-line :class:`ConfigError` unless ``address`` is ``local``, ``none`` or looks like a
    scheduler address (``tcp://host:8786``)."""
    if address in ("local", "none"):
        return
    if not address.startswith(SCHEDULER_SCHEMES) and ":" not in address:
        raise ConfigError(f"--scheduler {address!r}: expected 'local', 'none' or an address such "
                          "as tcp://host:8786")


def check_listen(host: str) -> None:
    """A one-line :class:`ConfigError` unless ``host`` names an IPv4 address of this machine.

    Resolved and test-bound here, before any cluster starts: an unknown host name or an address
    of another machine otherwise surfaced as Dask's "Cluster failed to start" after the workers
    had been launched. IPv6 is refused: Dask's LocalCluster does not start on ``::1`` (it asks for
    brackets).
    """
    where = f"--listen {host!r}"
    try:
        literal = ipaddress.ip_address(host)
    except ValueError:
        literal = None
        if not re.fullmatch(HOST_NAME_PATTERN, host):
            raise ConfigError(f"{where}: not an IP address or host name; allowed: {LISTEN_ALLOWED}") from None
        if re.fullmatch(r"[0-9.]+", host):  # 999.1.1.1 is a malformed address, not a name
            raise ConfigError(f"{where}: not an IPv4 address (four numbers 0-255 joined by '.'); "
                              f"allowed: {LISTEN_ALLOWED}")
    if literal is not None and literal.version != 4:
        raise ConfigError(f"{where}: an IPv6 address; allowed: {LISTEN_ALLOWED}")
    try:
        infos = socket.getaddrinfo(host, None, socket.AF_INET, socket.SOCK_STREAM)
    except (socket.gaierror, UnicodeError) as exc:
        reason = getattr(exc, "strerror", None) or str(exc) or type(exc).__name__
        raise ConfigError(f"{where}: cannot be resolved ({reason}); allowed: {LISTEN_ALLOWED}") from None
    errors = []
    for *_, sockaddr in infos:
        with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
            try:
                probe.bind((sockaddr[0], 0))  # port 0: any free one, released at once
                return
            except OSError as exc:
                errors.append(f"{sockaddr[0]}: {exc.strerror or exc}")
    raise ConfigError(f"{where}: not an address of this machine ({'; '.join(errors) or 'no IPv4 address'}); "
                      f"allowed: {LISTEN_ALLOWED}")


def connect_scheduler(address: str):
    """A Dask client of the scheduler at ``address``; a one-line ``ConfigError`` if none answers
    within :data:`SCHEDULER_CONNECT_TIMEOUT_S`."""
    from dask.distributed import Client

    check_scheduler(address)
    try:
        return Client(address, timeout=SCHEDULER_CONNECT_TIMEOUT_S)
    except (OSError, TimeoutError, ValueError) as exc:
        reason = " ".join(str(exc).split()) or type(exc).__name__
        raise ConfigError(f"--scheduler {address!r}: no Dask scheduler answered within "
                          f"{SCHEDULER_CONNECT_TIMEOUT_S:g} s ({reason[:200]})") from None


def local_cluster(n_workers: Optional[int] = None, listen: str = LOOPBACK):
    """The campaign's local Dask cluster: one single-threaded worker process per core.

    Scheduler, workers (and their nannies) and the status page all listen on ``listen``
    (loopback by default, so nothing is reachable from the network), each on a free port so two
    campaigns can run at once. The worker processes ignore SIGINT from their first instruction
    (they are started inside :class:`_SigintHeld`) and any worker the nannies start later does
    so from its start-up (:func:`dask_setup`, its preload), so a Ctrl-C reaches only this process.
    """
    import logging

    from dask.distributed import LocalCluster

    with _SigintHeld() as release:
        # Dask's own log lines are kept to the critical ones: at shutdown a worker whose heartbeat
        # meets the closing scheduler logs a three-part traceback at ERROR, which is noise; a failed
        # or lost run still surfaces through its future as a one-line error.
        cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, host=listen,
                               dashboard_address=f"{listen}:0", silence_logs=logging.CRITICAL,
                               preload=[__name__])
        try:
            release()  # a Ctrl-C held back while the cluster started is raised here
        except BaseException:
            cluster.close()
            raise
    return cluster


def dask_setup(worker) -> None:
    """Dask's preload hook, run in each worker process of :func:`local_cluster` as it starts:
    SIGINT is left to the campaign's own process, which shuts the cluster down."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)


class _SigintHeld:
    """For the block, SIGINT is ignored (so every process started meanwhile inherits "ignored",
    which survives exec and which Python and asyncio then leave alone) and blocked in this
    thread (so a Ctrl-C meanwhile stays pending rather than being discarded); ``release()`` (or
    the block's end) puts the handler back and then unblocks, raising that Ctrl-C.

    Dask starts its worker processes from threads it creates inside the block; those inherit
    the block too, so the signal stays pending for this thread. Only the main thread handles
    signals in Python: elsewhere (and without ``pthread_sigmask``) nothing is changed.
    """

    def __enter__(self):
        self._mask = self._handler = None
        if threading.current_thread() is threading.main_thread() and hasattr(signal, "pthread_sigmask"):
            self._mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
            self._handler = signal.signal(signal.SIGINT, signal.SIG_IGN)
        return self.release

    def release(self) -> None:
        """Restore the handler, then the mask (once); a pending Ctrl-C raises KeyboardInterrupt here."""
        mask, self._mask = self._mask, None
        if mask is not None:
            signal.signal(signal.SIGINT, signal.default_int_handler if self._handler is None else self._handler)
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)

    def __exit__(self, *exc) -> None:
        self.release()
