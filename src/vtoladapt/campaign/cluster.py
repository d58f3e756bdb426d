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
from typing import Any, Callable, Optional

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
    campaigns can run at once. The worker processes start with SIGINT blocked (they are started
    inside :class:`_SigintHeld`, and the nannies' later restarts from its threads) and ignore it
    from their preload (:func:`dask_setup`) on, so a Ctrl-C reaches only this process.
    """
    import logging

    from dask.distributed import LocalCluster

    # multiprocessing starts its resource tracker with SIGINT blocked and then *unblocks* it in the
    # starting thread: started inside the block, that unblocked Dask's threads and so the workers
    _start_resource_tracker()
    with _SigintHeld() as release:
        # Dask's own log lines are kept to the critical ones: at shutdown a worker whose heartbeat
        # meets the closing scheduler logs a three-part traceback at ERROR, which is noise; a failed
        # or lost run still surfaces through its future as a one-line error.
        cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, host=listen,
                               dashboard_address=f"{listen}:0", silence_logs=logging.CRITICAL,
                               preload=[__name__])
        _stop_gc_diagnosis()  # the scheduler runs in this process
        try:
            release()  # a Ctrl-C held back while the cluster started is raised here
        except KeyboardInterrupt:
            _abandon(None, cluster)  # workers still starting: a graceful close waited up to 10 s
            raise
        except BaseException:
            cluster.close()
            raise
    return cluster


INTERRUPT_CLOSE_TIMEOUT_S = 2.0
"""After Ctrl-C, how long the client and the local cluster each get to close (their runs are discarded;
the command then exits without waiting further, and the worker processes are already gone)."""


def run_on_dask(fn: Callable, items: list, scheduler: str, n_workers: Optional[int], listen: str,
                started: Callable[[], None], done: Callable[[Any], None]) -> None:
    """``fn`` over ``items`` on the local cluster (``scheduler == "local"``) or the scheduler at
    ``scheduler``; ``started()`` once it is up, ``done(result)`` per result as they finish.

    Ctrl-C at any point -- the cluster's start included (held by :class:`_SigintHeld` and raised
    once it is up) -- kills the local workers at once (:func:`stop_local_workers`) and gives the
    client and the cluster :data:`INTERRUPT_CLOSE_TIMEOUT_S` each to close, then raises
    KeyboardInterrupt; otherwise they are closed normally.
    """
    from dask.distributed import Client, as_completed

    cluster = client = None
    try:
        if scheduler == "local":
            cluster = local_cluster(n_workers, listen)
            client = Client(cluster)
        else:
            client = connect_scheduler(scheduler)
        started()
        for fut in as_completed(client.map(fn, items, pure=False)):
            done(fut.result())
    except KeyboardInterrupt:
        _abandon(client, cluster)
        raise
    except BaseException:
        _close(client, cluster)
        raise
    _close(client, cluster)


def _close(client, cluster) -> None:
    """Close normally; a Ctrl-C meanwhile abandons them as :func:`_abandon` does."""
    try:
        if client is not None:
            client.close()
        if cluster is not None:
            cluster.close()
    except KeyboardInterrupt:
        _abandon(client, cluster)
        raise


def _abandon(client, cluster) -> None:
    """After Ctrl-C: kill the local workers, give each a short close, never wait longer."""
    if cluster is not None:  # the runs are discarded: no need to wait for any of them
        stop_local_workers(cluster)
    for closing in (client, cluster):
        if closing is not None:
            try:
                closing.close(timeout=INTERRUPT_CLOSE_TIMEOUT_S)
            except BaseException:  # a close that times out, or a second Ctrl-C: the process is ending
                pass
    if cluster is not None:
        # Dask's exit handler closes every cluster it knows again, gracefully, for up to 10 s more:
        # this one's workers are gone, and the command is ending
        instances = getattr(type(cluster), "_instances", None)
        if instances is not None:
            instances.discard(cluster)


def stop_local_workers(cluster=None) -> None:
    """Kill this process's Dask worker processes at once: an interrupted campaign discards their
    runs, and a graceful close waited for the run (or the kernel loading) each was busy with, up to
    10 s after Ctrl-C. Only children this process spawned through multiprocessing are touched. The
    cluster's nannies are told first that the cluster is closing, or each would start a new worker
    in place of the one killed (and the close would wait for it)."""
    import contextlib

    import psutil

    for nanny in list(getattr(cluster, "workers", {}).values()):
        with contextlib.suppress(Exception):
            nanny.close_gracefully(reason="vtoladapt: interrupted")

    try:
        children = psutil.Process().children()
    except psutil.Error:
        return
    workers = []
    for child in children:
        try:
            if "spawn_main" in " ".join(child.cmdline()):
                child.kill()
                workers.append(child)
        except psutil.Error:  # already gone
            continue
    psutil.wait_procs(workers, timeout=5)


def _start_resource_tracker() -> None:
    try:
        from multiprocessing import resource_tracker

        resource_tracker.ensure_running()
    except (ImportError, OSError):  # no tracker on this platform: nothing to unblock
        pass


def dask_setup(worker) -> None:
    """Dask's preload hook, run in each worker process of :func:`local_cluster` as it starts:
    SIGINT is left to the campaign's own process, which shuts the cluster down."""
    _stop_gc_diagnosis()
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)  # discards a Ctrl-C held pending since the start
        if hasattr(signal, "pthread_sigmask"):
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def _stop_gc_diagnosis() -> None:
    """Turn off Dask's garbage-collection timing in this process (a scheduler or worker starts it).

    It only logs how long collections take, and its callback asserts that every collection's start is
    followed by its stop; a collection that begins while another is being timed (seen during a
    campaign whose kernels compiled as it started) printed "Exception ignored in GCDiagnosis._gc_callback
    ... AssertionError" with a traceback into the user's terminal."""
    from distributed.gc import disable_gc_diagnosis

    disable_gc_diagnosis(force=True)


class _SigintHeld:
    """For the block, SIGINT is blocked in this thread and only remembered by its handler;
    ``release()`` (or the block's end) unblocks it, puts the handler back and raises
    KeyboardInterrupt if a Ctrl-C came meanwhile.

    Processes started meanwhile (Dask's worker processes, spawned from threads Dask creates inside
    the block, which inherit the mask) start with SIGINT blocked, a mask that survives ``exec``:
    a Ctrl-C to the process group stays pending in them until their preload (:func:`dask_setup`)
    ignores it, which discards it, so no worker prints a traceback.

    The signal is never set to "ignored" in this process: a process-wide SIGINT is delivered to a
    thread that does not block it -- native threads of numerical libraries started earlier do not --
    and an ignored one was dropped there (a Ctrl-C 1.5-2 s into a campaign was lost, issue #27).
    With the handler installed, such a delivery runs the handler in the main thread as always.
    Only the main thread handles signals in Python: elsewhere (and without ``pthread_sigmask``)
    nothing is changed.
    """

    def __enter__(self):
        self._mask = self._handler = None
        self._pending = False
        if threading.current_thread() is threading.main_thread() and hasattr(signal, "pthread_sigmask"):
            self._handler = signal.signal(signal.SIGINT, self._remember)
            self._mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        return self.release

    def _remember(self, signum, frame) -> None:
        self._pending = True

    def release(self) -> None:
        """Unblock, restore the handler (once); a Ctrl-C held meanwhile raises KeyboardInterrupt here."""
        mask, self._mask = self._mask, None
        if mask is None:
            return
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)  # one pending reaches _remember now
        signal.signal(signal.SIGINT, signal.default_int_handler if self._handler is None else self._handler)
        if self._pending:
            self._pending = False
            raise KeyboardInterrupt

    def __exit__(self, *exc) -> None:
        self.release()
