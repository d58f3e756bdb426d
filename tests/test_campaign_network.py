"""The campaign's local Dask cluster is reachable from this machine only."""
from __future__ import annotations

import ipaddress

import pytest

psutil = pytest.importorskip("psutil")


def _listening_addresses(pids: set[int]) -> list[tuple[int, str, int]]:
    found = []
    for conn in psutil.net_connections(kind="inet"):
        if conn.pid in pids and conn.status == psutil.CONN_LISTEN:
            found.append((conn.pid, conn.laddr.ip, conn.laddr.port))
    return found


def test_local_cluster_listens_on_loopback_only():
    """Scheduler, worker, nanny and status-page sockets: all inside 127.0.0.0/8.

    The cluster is the one ``vtoladapt campaign`` starts (:func:`local_cluster`); before the
    fix its status page listened on 0.0.0.0.
    """
    from dask.distributed import Client

    from vtoladapt.campaign.cluster import local_cluster

    with local_cluster(n_workers=2) as cluster, Client(cluster):
        me = psutil.Process()
        pids = {me.pid} | {p.pid for p in me.children(recursive=True)}
        sockets = _listening_addresses(pids)
    # scheduler + dashboard in this process, and a worker and a nanny per worker process
    assert len(sockets) >= 4, sockets
    loopback = ipaddress.ip_network("127.0.0.0/8")
    outside = [s for s in sockets if ipaddress.ip_address(s[1]) not in loopback]
    assert not outside, f"listening outside loopback: {outside}"
