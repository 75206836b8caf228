"""--cluster: the Dask scheduler a study's or tuning's HIL runs go to, and how armctl talks to it.

A Dask scheduler runs whatever task a client sends it, as the user its workers run as. So armctl
speaks to a scheduler off this host only over TLS with mutual authentication (Dask's
`distributed.security.Security`, `tls://`): every party holds a certificate of the study's own CA,
and nobody else gets in. Plain `tcp://` is for a scheduler on loopback, or when the user says
`--insecure-cluster`. `armctl cluster-certs --out DIR` makes that CA and the certificates.
"""

from __future__ import annotations

import argparse
import ipaddress
import os
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

DEFAULT_PORT = 8786
# The files `armctl cluster-certs` writes: the CA's certificate, then a certificate and key for
# each party (every worker shares worker.*). The CA's own key is not kept: nothing can be signed
# into the study later; a new folder is a new CA.
PARTIES = ("scheduler", "worker", "client")
CERT_DAYS = 365


class ClusterError(ValueError):
    """--cluster or its TLS options cannot be used as given; the message says which and why."""


@dataclass(frozen=True)
class Cluster:
    address: str                             # tls://HOST:PORT or tcp://HOST:PORT
    tls: tuple[str, str, str] | None = None  # the CA, this client's certificate and key (PEM files)

    def security(self) -> Any:
        """Dask's Security for the client: TLS required, the scheduler's certificate checked
        against the CA; None for tcp://."""
        if self.tls is None:
            return None
        from distributed.security import Security

        ca, cert, key = self.tls
        return Security(tls_ca_file=ca, tls_client_cert=cert, tls_client_key=key, require_encryption=True)


def add_cluster_arguments(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("a Dask cluster (docs/study.md: Parallel and distributed)")
    g.add_argument("--cluster", default=None, metavar="ADDRESS",
                   help="a Dask scheduler (tls://HOST:8786, with --tls-*): each HIL run is a task on its workers")
    g.add_argument("--tls-ca", type=Path, default=None, metavar="FILE", help="the cluster's CA certificate (PEM)")
    g.add_argument("--tls-cert", type=Path, default=None, metavar="FILE", help="this client's certificate (PEM)")
    g.add_argument("--tls-key", type=Path, default=None, metavar="FILE", help="this client's private key (PEM)")
    g.add_argument("--insecure-cluster", action="store_true",
                   help="allow a plain tcp:// scheduler off this host: anyone who reaches it runs code as its workers")


def _is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False  # a name: where it resolves to is not this host's to promise


def check_cluster(address: str | None, ca: Path | None = None, cert: Path | None = None, key: Path | None = None,
                  insecure: bool = False) -> Cluster | None:
    """The cluster to use, checked before anything builds or connects."""
    files = {"--tls-ca": ca, "--tls-cert": cert, "--tls-key": key}
    given = {k: v for k, v in files.items() if v is not None}
    if address is None:
        if given:
            raise ClusterError(f"{', '.join(given)}: only with --cluster tls://HOST:{DEFAULT_PORT}")
        return None
    scheme, sep, rest = address.partition("://")
    if not sep:
        scheme, rest = "tcp", address  # Dask's default
    try:
        parts = urlsplit(f"//{rest}")
        host, port = parts.hostname, parts.port
    except ValueError as exc:
        raise ClusterError(f"--cluster {address}: not an address HOST:PORT ({exc})") from None
    if scheme not in ("tls", "tcp") or not host or parts.path or parts.query:
        raise ClusterError(f"--cluster {address}: expected tls://HOST:PORT (or tcp://HOST:PORT on loopback)")
    norm = f"{scheme}://{rest}" if port is not None else f"{scheme}://{rest}:{DEFAULT_PORT}"
    if scheme == "tcp":
        if given:
            raise ClusterError(f"--cluster {address}: {', '.join(given)} given but the address is tcp://; "
                               "use tls://")
        if not _is_loopback(host) and not insecure:
            raise ClusterError(f"--cluster {address}: plain tcp:// to another host is refused (no encryption, no "
                               "authentication: anyone who reaches the scheduler runs code as its workers); use "
                               "tls:// with --tls-ca/--tls-cert/--tls-key (armctl cluster-certs), or "
                               "--insecure-cluster")
        return Cluster(norm)
    missing = [k for k, v in files.items() if v is None]
    if missing:
        raise ClusterError(f"--cluster {address}: tls:// needs {', '.join(missing)} (armctl cluster-certs makes them)")
    for opt, path in files.items():
        assert path is not None
        if not path.is_file() or not os.access(path, os.R_OK):
            raise ClusterError(f"{opt} {path}: no such readable file")
    assert ca is not None and cert is not None and key is not None
    return Cluster(norm, (str(ca.resolve()), str(cert.resolve()), str(key.resolve())))


def cluster_from_args(ns: argparse.Namespace) -> Cluster | None:
    return check_cluster(getattr(ns, "cluster", None), getattr(ns, "tls_ca", None), getattr(ns, "tls_cert", None),
                         getattr(ns, "tls_key", None), getattr(ns, "insecure_cluster", False))


def cert_files(folder: Path) -> list[Path]:
    return [folder / "ca.pem", *(folder / f"{p}.{ext}" for p in PARTIES for ext in ("pem", "key"))]


def _openssl(args: list[str], cwd: Path) -> None:
    r = subprocess.run(["openssl", *args], cwd=cwd, capture_output=True, text=True)
    if r.returncode != 0:
        raise ClusterError(f"openssl {args[0]}: {(r.stderr.strip().splitlines() or ['failed'])[-1]}")


def make_certs(folder: Path, days: int = CERT_DAYS) -> list[Path]:
    """A CA of its own and a certificate and key (EC P-256) for the scheduler, the workers and the
    client, signed by it, in `folder`. Refuses to replace any of them; on failure writes none."""
    if shutil.which("openssl") is None:
        raise ClusterError("openssl not found: apt-get install openssl")
    out = cert_files(folder)
    if existing := [p for p in out if p.exists()]:
        raise ClusterError(f"--out {folder}: {existing[0].name} exists already; give an empty folder")
    folder.mkdir(parents=True, exist_ok=True)
    ec = ["-newkey", "ec", "-pkeyopt", "ec_paramgen_curve:prime256v1", "-nodes"]
    with tempfile.TemporaryDirectory(dir=folder, prefix=".armctl-certs-") as tmp_s:
        tmp = Path(tmp_s)
        _openssl(["req", "-x509", *ec, "-keyout", "ca.key", "-out", "ca.pem", "-days", str(days),
                  "-subj", "/CN=armctl study CA", "-addext", "basicConstraints=critical,CA:TRUE",
                  "-addext", "keyUsage=critical,keyCertSign,cRLSign"], tmp)
        (tmp / "leaf.ext").write_text("basicConstraints=CA:FALSE\nkeyUsage=critical,digitalSignature\n"
                                      "extendedKeyUsage=serverAuth,clientAuth\n")
        for party in PARTIES:
            _openssl(["req", *ec, "-keyout", f"{party}.key", "-out", f"{party}.csr",
                      "-subj", f"/CN=armctl {party}"], tmp)
            _openssl(["x509", "-req", "-in", f"{party}.csr", "-CA", "ca.pem", "-CAkey", "ca.key",
                      "-set_serial", str(int.from_bytes(os.urandom(8), "big")), "-days", str(days),
                      "-extfile", "leaf.ext", "-out", f"{party}.pem"], tmp)
        for p in out:
            os.chmod(tmp / p.name, 0o600 if p.suffix == ".key" else 0o644)
        for p in out:
            os.replace(tmp / p.name, p)
    return out


def add_subparser(sub: argparse._SubParsersAction) -> None:
    cc = sub.add_parser("cluster-certs", help="a CA and TLS certificates for a Dask cluster (study/tune --cluster tls://)")
    cc.add_argument("--out", type=Path, required=True, help="an empty folder for ca.pem and scheduler/worker/client .pem/.key")
    cc.set_defaults(run=run)


def run(ns: argparse.Namespace) -> int:
    """armctl cluster-certs (a ClusterError exits 2, an OSError 1: tools/cli.py)."""
    files = make_certs(ns.out)
    print(f"armctl cluster-certs: a CA and certificates for the scheduler, the workers and the client in {ns.out}: "
          + ", ".join(p.name for p in files) + " (the .key files are secrets: copy each only to where it is used)")
    return 0
