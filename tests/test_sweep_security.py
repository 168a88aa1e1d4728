"""The local Dask cluster of `rodwarp sweep` admits only its own clients (issue 29, class 9).

Loopback alone let any local process connect to the scheduler and run code on its workers.
The cluster now speaks TLS with mutual authentication, on credentials made in memory for it
alone (distributed.security.Security.temporary): a client without them is refused, with
them it works. A cluster given by address (``--scheduler tcp://...``) is used as before.
"""

from __future__ import annotations

import pytest

# distributed and cryptography are dependencies of rodwarp: a missing one must fail here, not skip
from distributed import Client, LocalCluster

from rodwarp.experiments._sweep import LOCAL_CLUSTER, _connect, _local_cluster


@pytest.fixture(scope="module")
def sweep_cluster():
    # one worker process, shared by the tests of this file (each start costs a second or two)
    cluster, client = _local_cluster(1)
    try:
        yield cluster, client
    finally:
        client.close()
        cluster.close()


def _add(x):
    return x + 1


def test_the_sweeps_cluster_speaks_tls_and_works_with_its_credentials(sweep_cluster):
    cluster, client = sweep_cluster
    address = cluster.scheduler_address
    assert address.startswith("tls://127.0.0.1:")
    assert cluster.security.require_encryption
    assert client.submit(_add, 1).result() == 2  # the sweep's own client
    # a second client given the cluster's credentials connects and runs a task: the refusals
    # below are the credentials' doing, not a cluster that refuses everyone
    with Client(address, security=cluster.security, timeout="10s") as other:
        assert other.submit(_add, 2).result() == 3
    assert "TLS" in LOCAL_CLUSTER and "127.0.0.1" in LOCAL_CLUSTER  # what sweep.json records


#: another local process: it tries the scheduler at argv[1] each way and prints what happened
#: as JSON. A process of its own, as an intruder would be; and in-process, a Client that
#: failed to connect can hang this process when the garbage collector closes it later.
_INTRUDER = r"""
import json, os, sys
from distributed import Client
from distributed.security import Security
from rodwarp.errors import RodwarpError
from rodwarp.experiments._sweep import _connect

address, creds = sys.argv[1], json.load(open(sys.argv[2]))

def attempt(addr, security=None):
    # a Client that failed to start is finalised here, not by a garbage collection that runs
    # while the next Client starts its loop (Dask then deadlocks in LoopRunner.stop)
    import gc
    gc.collect()
    try:
        c = Client(addr, timeout="5s", **({"security": security} if security is not None else {}))
    except Exception as e:
        return "refused: " + type(e).__name__
    finally:
        gc.collect()
    try:
        return "ran: " + str(c.submit(sum, [1, 2]).result(timeout=20))
    finally:
        c.close()

def raw_tls(addr, cert=None, key=None):
    # a TLS client of its own that trusts anything; without a certificate the server must end
    # the connection (with the cluster's, Dask's handshake message comes back)
    import socket, ssl
    host, port = addr.split("://", 1)[1].rsplit(":", 1)
    ctx = ssl.SSLContext(ssl.PROTOCOL_TLS_CLIENT)
    ctx.check_hostname, ctx.verify_mode = False, ssl.CERT_NONE
    if cert:
        ctx.load_cert_chain(cert, key)
    try:
        with socket.create_connection((host, int(port)), timeout=5) as s, ctx.wrap_socket(s) as t:
            t.settimeout(5)
            data = t.recv(64)
            return f"answered: {len(data)} bytes" if data else "refused: closed"
    except socket.timeout:
        return "silent"
    except (ssl.SSLError, OSError) as e:
        return "refused: " + type(e).__name__

try:
    _connect(address, timeout=3)
    connect = "connected"
except RodwarpError as e:
    connect = "error: " + str(e)
out = {
    "no credentials": attempt(address),
    "plain tcp": attempt(address.replace("tls://", "tcp://", 1)),
    # a self-signed pair of its own, not signed by the cluster's
    "other credentials": attempt(address, Security.temporary()),
    # the cluster's certificate (public) without its key: no client certificate to present
    "its CA, no key": attempt(address, Security(require_encryption=True, tls_ca_file=creds["ca"])),
    "raw TLS, no certificate": raw_tls(address),
    "raw TLS, its certificate": raw_tls(address, creds["cert_file"], creds["key_file"]),
    # the control: given the cluster's credentials, the same process connects and runs a task
    "its credentials": attempt(address, Security(require_encryption=True, tls_ca_file=creds["ca"],
                                                 tls_client_cert=creds["cert"], tls_client_key=creds["key"])),
    "_connect": connect,
}
print("RESULT " + json.dumps(out), flush=True)
os._exit(0)  # no interpreter shutdown: failed clients' finalizers are not this test's subject
"""


def test_a_process_without_the_credentials_cannot_connect(sweep_cluster, tmp_path):
    import json
    import subprocess
    import sys

    cluster, _ = sweep_cluster
    sec = cluster.security
    creds = tmp_path / "creds.json"
    (tmp_path / "cert.pem").write_text(sec.tls_client_cert)
    (tmp_path / "key.pem").write_text(sec.tls_client_key)
    creds.write_text(json.dumps({"ca": sec.tls_ca_file, "cert": sec.tls_client_cert, "key": sec.tls_client_key,
                                 "cert_file": str(tmp_path / "cert.pem"), "key_file": str(tmp_path / "key.pem")}))
    script = tmp_path / "intruder.py"
    script.write_text(_INTRUDER)
    proc = subprocess.run([sys.executable, str(script), cluster.scheduler_address, str(creds)], capture_output=True,
                          text=True, timeout=120)
    line = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    assert line, proc.stdout + proc.stderr
    got = json.loads(line[0][len("RESULT "):])
    for how in ("no credentials", "plain tcp", "other credentials", "its CA, no key", "raw TLS, no certificate"):
        assert got[how].startswith("refused: "), (how, got[how])
    assert got["its credentials"] == "ran: 3"
    assert got["raw TLS, its certificate"].startswith("answered: "), got["raw TLS, its certificate"]
    # `--scheduler tls://...` without credentials: one line that names the cause
    assert got["_connect"].startswith("error: --scheduler tls://") and "credentials" in got["_connect"]
    assert "\n" not in got["_connect"]


def test_connect_to_a_cluster_given_by_tcp_address_still_works():
    # `rodwarp sweep --scheduler tcp://HOST:PORT`: an existing plain cluster is the user's
    # choice, connected as before (threads in this process: no worker start-up to wait for)
    with LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp://", host="127.0.0.1",
                      dashboard_address=None) as cluster:
        assert cluster.scheduler_address.startswith("tcp://")
        client = _connect(cluster.scheduler_address)
        try:
            assert client.submit(_add, 41).result() == 42
        finally:
            client.close()
