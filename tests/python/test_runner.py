"""Many runs at once: each in a run slot of its own (its bus and telemetry ports, guaranteed), on
threads of this process or as tasks on a Dask cluster, with the same results either way."""

from __future__ import annotations

import fcntl
import hashlib
import json
import os
import shutil
import threading
from dataclasses import asdict, replace
from pathlib import Path

import pytest

from tools.run.cluster import ClusterError, cert_files, check_cluster, make_certs
from tools.run.hil import HilOptions, run_hil
from gen.lib.paths import REPO
from tools.run.runner import RunSpec, execute, run_all
from tools.run.slots import CAN_BASE, LCM_BASE, _lock_dir, acquire_slot


@pytest.mark.serial  # alone: it expects the lowest free slot to stay free meanwhile
def test_a_taken_slot_is_skipped_and_released_on_exit() -> None:
    with acquire_slot() as a:
        with acquire_slot() as b:
            assert a.index != b.index
            assert {a.can_port, b.can_port} <= set(range(CAN_BASE, CAN_BASE + 8 * 64, 8))
            assert abs(a.lcm_port - b.lcm_port) >= 1 and min(a.lcm_port, b.lcm_port) >= LCM_BASE
        with acquire_slot() as c:
            assert c.index == b.index  # b's slot is free again
    # a slot held by another process (an flock on its file) is never handed out
    path = _lock_dir() / f"slot-{a.index}.lock"
    fd = os.open(path, os.O_RDWR | os.O_CREAT)
    fcntl.flock(fd, fcntl.LOCK_EX)
    try:
        with acquire_slot() as d:
            assert d.index != a.index
    finally:
        os.close(fd)


def test_runs_side_by_side_never_hear_each_other(tmp_path: Path) -> None:
    """Two runs at once: each controller hears exactly its own simulator's frames (no frame of
    the other run is counted on either side), and both give the result they give alone."""
    # the arm protocol: its drives' heartbeats are counted per period (the CiA 402 drives' go by the
    # wall clock, so two runs at once count more of them than one alone)
    alone = run_hil(HilOptions(out=tmp_path / "alone", duration_s=1.0, method="tde", protocol="arm"))
    runs: dict[str, dict] = {}

    def one(name: str) -> None:
        runs[name] = run_hil(HilOptions(out=tmp_path / name, duration_s=1.0, method="tde", protocol="arm"))

    threads = [threading.Thread(target=one, args=(n,)) for n in ("a", "b")]
    for t in threads:
        t.start()
    for t in threads:
        t.join(300)
    buses = {runs[n]["environment"]["bus"] for n in ("a", "b")}
    assert len(buses) == 2  # distinct ports
    solo = alone["transport"]["controller_frames"]
    for n in ("a", "b"):
        r = runs[n]
        assert r["results"]["result"] == "ok"
        assert r["results"]["tracking_max_abs_rad"] == alone["results"]["tracking_max_abs_rad"]
        ctl, sim = r["transport"]["controller_frames"], r["transport"]["simulator_frames"]
        # another run's frames would be states of other periods, a second SYNC/command source,
        # or twice the states: none, and exactly the states the run alone got
        assert ctl["rx_wrong_counter"] == ctl["rx_foreign_master"] == ctl["rx_unknown_id"] == 0, ctl
        assert sim["rx_foreign_drive"] == sim["rx_unknown_id"] == 0, sim
        # the drives' boot-up heartbeats (one per drive) reach the controller only when it is already
        # listening: whether it is depends on how fast each process starts, so one round may differ
        boot_round = len(r["results"]["joint_names"])
        assert ctl["rx_state"] == solo["rx_state"]
        assert abs(ctl["rx_heartbeat"] - solo["rx_heartbeat"]) in (0, boot_round), (ctl, solo)


def _spec(out: Path, seed: int) -> RunSpec:
    return RunSpec(out=str(out), method="pm", duration_s=0.3, controller_args=("--ref-hold", "0.2"),
                   uncertainty={"paper_ratio": 0.05, "paper_knot_s": 0.05, "seed": seed})


def test_a_run_with_its_spec_kept_is_not_run_again(tmp_path: Path) -> None:
    spec = _spec(tmp_path / "r", 3)
    first = execute(asdict(spec))
    stamp = (tmp_path / "r" / "run.json").stat().st_mtime_ns
    assert execute(asdict(spec)) == first and (tmp_path / "r" / "run.json").stat().st_mtime_ns == stamp
    changed = _spec(tmp_path / "r", 4)  # another seed in the same folder: run again
    assert execute(asdict(changed))["results"]["uncertainty"]["seed"] == 4


def _edit_run(folder: Path, edit, rechecksum: bool = False) -> None:  # noqa: ANN001 - edit(results) in place
    run = json.loads((folder / "run.json").read_text())
    edit(run["results"])
    (folder / "run.json").write_text(json.dumps(run, indent=2) + "\n")
    if rechecksum:  # as if spec.json had been forged to match: the run.json's own content must still hold
        done = json.loads((folder / "spec.json").read_text())
        done["run_json_sha256"] = hashlib.sha256((folder / "run.json").read_bytes()).hexdigest()
        (folder / "spec.json").write_text(json.dumps(done))


def test_a_kept_run_is_reused_only_if_it_is_the_run_its_spec_made(tmp_path: Path,
                                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """An edited metric, a run.json of another method, a string metric, an interrupted run, a run
    without spec.json: each is run again, with one line saying why; the rerun gives the original."""
    pm = _spec(tmp_path / "pm", 3)
    pd = replace(_spec(tmp_path / "pd", 3), method="pd", labels={"method": "pd"})
    first = {s.method: execute(asdict(s)) for s in (pm, pd)}
    capsys.readouterr()
    linf = first["pm"]["results"]["tracking_max_abs_rad"]

    def again(spec: RunSpec, why: str) -> None:
        run = execute(asdict(spec))
        err = capsys.readouterr().err
        lines = [ln for ln in err.splitlines() if "running it again" in ln]
        assert len(lines) == 1 and why in lines[0] and spec.out in lines[0], err
        assert run["results"]["tracking_max_abs_rad"] == first[spec.method]["results"]["tracking_max_abs_rad"]
        assert execute(asdict(spec)) == run and "running it again" not in capsys.readouterr().err  # now kept

    _edit_run(tmp_path / "pm", lambda r: r.update(tracking_max_abs_rad=[100 * x for x in linf]))
    again(pm, "checksum")
    shutil.copy(tmp_path / "pd" / "run.json", tmp_path / "pm" / "run.json")  # pd's run in pm's folder
    again(pm, "its method differ")
    _edit_run(tmp_path / "pm", lambda r: r.update(torque_power_w="1.5"), rechecksum=True)
    again(pm, "torque_power_w not numbers")
    _edit_run(tmp_path / "pm", lambda r: r.update(result="interrupted"), rechecksum=True)
    again(pm, "ended interrupted")
    (tmp_path / "pm" / "spec.json").unlink()
    again(pm, "did not finish")


def test_the_same_runs_on_a_dask_cluster(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """A local Dask cluster of two worker processes, over TLS with the certificates `armctl
    cluster-certs` makes (docs/study.md's set-up): every run is a task, the results are the ones the
    threads give; a client without a certificate of the study's CA is not let in."""
    distributed = pytest.importorskip("distributed")
    from distributed.security import Security

    monkeypatch.setenv("PYTHONPATH", str(REPO))  # the workers import tools.run.runner from this checkout
    tls = tmp_path / "tls"
    make_certs(tls)
    f = {p.name: str(p) for p in cert_files(tls)}
    security = Security(tls_ca_file=f["ca.pem"], tls_scheduler_cert=f["scheduler.pem"],
                        tls_scheduler_key=f["scheduler.key"], tls_worker_cert=f["worker.pem"],
                        tls_worker_key=f["worker.key"], tls_client_cert=f["client.pem"],
                        tls_client_key=f["client.key"], require_encryption=True)  # the client: LocalCluster's own
    specs_local = [_spec(tmp_path / "local" / str(s), s) for s in (1, 2, 3)]
    specs_dask = [_spec(tmp_path / "dask" / str(s), s) for s in (1, 2, 3)]
    local = run_all(specs_local, jobs=2)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                  protocol="tls", host="127.0.0.1", security=security) as cl:
        assert cl.scheduler_address.startswith("tls://127.0.0.1:")
        cluster = check_cluster(cl.scheduler_address, tls / "ca.pem", tls / "client.pem", tls / "client.key")
        remote = run_all(specs_dask, cluster=cluster)
        # a certificate of another CA: the scheduler refuses the handshake
        other = tmp_path / "other"
        make_certs(other)
        stranger = Security(tls_ca_file=str(other / "ca.pem"), tls_client_cert=str(other / "client.pem"),
                            tls_client_key=str(other / "client.key"), require_encryption=True)
        with pytest.raises(OSError):
            distributed.Client(cl.scheduler_address, security=stranger, timeout=5)
    assert [r["results"]["tracking_max_abs_rad"] for r in remote] == [r["results"]["tracking_max_abs_rad"] for r in local]
    assert all((tmp_path / "dask" / str(s) / "run.json").exists() for s in (1, 2, 3))


@pytest.mark.parametrize(("address", "kw", "named"), [
    ("tcp://10.1.2.3:8786", {}, "plain tcp:// to another host is refused"),
    ("10.1.2.3:8786", {}, "plain tcp:// to another host is refused"),
    ("tcp://scheduler.lan:8786", {}, "plain tcp:// to another host is refused"),
    ("tls://10.1.2.3:8786", {}, "tls:// needs --tls-ca, --tls-cert, --tls-key"),
    ("tls://10.1.2.3:8786", {"ca": Path("/nonexistent/ca.pem"), "cert": Path("/etc/hostname"),
                             "key": Path("/etc/hostname")}, "--tls-ca /nonexistent/ca.pem: no such readable file"),
    ("tcp://127.0.0.1:8786", {"ca": Path("/etc/hostname")}, "given but the address is tcp://"),
    ("ws://127.0.0.1:8786", {}, "expected tls://HOST:PORT"),
    ("tls://10.1.2.3:99999", {}, "not an address"),
    (None, {"ca": Path("/etc/hostname")}, "only with --cluster"),
])
def test_a_cluster_without_tls_off_this_host_is_refused(address: str | None, kw: dict, named: str) -> None:
    with pytest.raises(ClusterError) as exc:
        check_cluster(address, **kw)
    assert named in str(exc.value) and "\n" not in str(exc.value)


def test_loopback_or_insecure_cluster_is_allowed_over_tcp() -> None:
    assert check_cluster("tcp://127.0.0.1:8786").address == "tcp://127.0.0.1:8786"
    assert check_cluster("tcp://[::1]").address == "tcp://[::1]:8786"
    assert check_cluster("localhost:8786").tls is None
    assert check_cluster("tcp://10.1.2.3:8786", insecure=True).address == "tcp://10.1.2.3:8786"


def test_armctl_refuses_a_plain_tcp_cluster_in_one_line(tmp_path: Path) -> None:
    import subprocess

    for cmd in ("study", "tune"):
        r = subprocess.run([str(REPO / "tools" / "armctl"), cmd, "--cluster", "tcp://10.1.2.3:8786", "--out",
                            str(tmp_path / cmd)], cwd=REPO, capture_output=True, text=True, timeout=120)
        assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1, r.stderr
        assert "tcp://10.1.2.3:8786" in r.stderr and "--insecure-cluster" in r.stderr
        assert not (tmp_path / cmd).exists()


def test_cluster_certs_make_a_ca_and_refuse_to_overwrite(tmp_path: Path) -> None:
    """`armctl cluster-certs`: every certificate verifies against the CA, keys are private, and a
    second run into the same folder changes nothing and says which file is in the way."""
    import subprocess

    out = tmp_path / "tls"
    r = subprocess.run([str(REPO / "tools" / "armctl"), "cluster-certs", "--out", str(out)], cwd=REPO,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in out.iterdir()) == sorted(p.name for p in cert_files(out))
    for party in ("scheduler", "worker", "client"):
        v = subprocess.run(["openssl", "verify", "-CAfile", str(out / "ca.pem"), str(out / f"{party}.pem")],
                           capture_output=True, text=True)
        assert v.returncode == 0, v.stdout + v.stderr
        assert (out / f"{party}.key").stat().st_mode & 0o077 == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    r = subprocess.run([str(REPO / "tools" / "armctl"), "cluster-certs", "--out", str(out)], cwd=REPO,
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "ca.pem exists" in r.stderr
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


@pytest.mark.serial  # alone: it expects the lowest free slot to stay free meanwhile
def test_a_slot_whose_ports_still_carry_traffic_is_passed_over() -> None:
    """An orphaned run (its armctl killed before the children followed) keeps sending on its slot's
    ports although the slot's lock is free: a new run must not take that slot."""
    import socket
    import threading
    import time

    from tools.run.slots import CAN_GROUP, acquire_slot

    with acquire_slot() as probe:
        free = probe.index  # the slot a run would take next
    stop = threading.Event()

    def orphan() -> None:
        s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, 0)
        s.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton("127.0.0.1"))
        while not stop.is_set():
            s.sendto(b"frame", (CAN_GROUP, probe.can_port))
            time.sleep(0.0005)
        s.close()

    t = threading.Thread(target=orphan)
    t.start()
    try:
        time.sleep(0.05)
        with acquire_slot(quiet_ports=True) as slot:
            assert slot.index != free
        with acquire_slot() as slot:  # software in the loop needs no ports: any free slot
            assert slot.index == free
    finally:
        stop.set()
        t.join()
