"""The Dask side of a sweep: a client of a given scheduler, or a local cluster of its own
(loopback, TLS with temporary credentials, no HTTP servers)."""

from __future__ import annotations

from rodwarp.errors import RodwarpError


def _stop_http(dask_worker=None, dask_scheduler=None) -> None:
    node = dask_worker or dask_scheduler
    server = getattr(node, "http_server", None)
    if server is not None:
        server.stop()


def _connect(address: str, timeout: float = 5.0):
    """A Client of the scheduler at ``address``, or a one-line error within ``timeout`` s.

    The TCP check of :func:`rodwarp.experiments.check_scheduler` comes first; this catches a
    port that accepts connections but does not speak Dask (a proxy, another service)."""
    from distributed import Client

    try:
        return Client(address, timeout=f"{timeout:g}s")
    except Exception as e:  # noqa: BLE001 - distributed raises OSError, TimeoutError, even MemoryError here
        if address.startswith("tls://"):
            # a TLS scheduler refuses a client without its credentials (TypeError: no ssl_context)
            raise RodwarpError(f"--scheduler {address}: no TLS connection to a Dask scheduler within {timeout:g} s "
                               f"({type(e).__name__}); give the cluster's credentials in the Dask config "
                               f"(distributed.comm.tls.*) or check the address") from None
        raise RodwarpError(f"--scheduler {address}: no Dask scheduler answers there within {timeout:g} s "
                           f"({type(e).__name__}); start one with `dask scheduler` or check the address") from None


#: what ``sweep.json`` records as the scheduler of a sweep on its own local cluster
#: (:func:`_local_cluster`): loopback only, and TLS with credentials made for that one cluster
LOCAL_CLUSTER = "LocalCluster(127.0.0.1, TLS with temporary credentials)"


def _local_cluster(n_workers: int):
    """A LocalCluster of single-threaded worker processes on 127.0.0.1, TLS-only, with no HTTP server.

    Parameters
    ----------
    n_workers : int
        Worker processes (one thread each).

    Returns
    -------
    cluster : distributed.LocalCluster
        The cluster; its ``security`` holds the credentials (close it when done).
    client : distributed.Client
        A client of the cluster, connected with the same credentials.

    Notes
    -----
    Loopback alone is no access control: any local process (another user's included) could
    connect to a plain ``tcp://`` scheduler and run code on its workers, with the rights of
    the user who started the sweep. So the cluster speaks TLS with mutual authentication
    (:meth:`distributed.security.Security.temporary`): a self-signed key and certificate made
    in memory for this cluster, required of every client, worker and nanny; a process without
    them cannot complete the handshake. ``sweep.json`` says so (:data:`LOCAL_CLUSTER`).

    distributed always starts an HTTP server on the scheduler (port 8787: /metrics, /health,
    /info even without a dashboard) and on each worker; a sweep on this machine needs none,
    so no routes are mounted and the servers are stopped once the cluster is up.
    """
    import dask
    from distributed import Client, LocalCluster
    from distributed.security import Security

    try:
        security = Security.temporary()
    except ImportError as e:  # cryptography is a dependency of rodwarp, but a broken install may lack it
        raise RodwarpError(f"the sweep's local cluster needs TLS credentials, which need the 'cryptography' "
                           f"package ({e}); install it (`pip install cryptography`) or give --scheduler") from None
    with dask.config.set({"distributed.scheduler.http.routes": [], "distributed.worker.http.routes": []}):
        # a random loopback port (not 8787, which another cluster may hold) for the server
        # that is stopped below
        cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                               protocol="tls://", security=security,
                               dashboard_address=None, worker_dashboard_address=None,
                               scheduler_kwargs={"dashboard": False, "dashboard_address": "127.0.0.1:0"})
    try:
        client = Client(cluster, security=security)
        _stop_http(dask_scheduler=cluster.scheduler)
        client.run(_stop_http)
    except BaseException:
        cluster.close()  # its worker processes would outlive the error otherwise
        raise
    return cluster, client
