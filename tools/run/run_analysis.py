"""Turn a HIL run's LCM log and the two processes' summaries into run.json.

run.json has three parts: `results` (everything a lockstep run determines: the same seed gives
the same numbers), `transport` (frame and telemetry accounting) and `environment` (ports, wall
time: what differs between two runs of the same configuration).
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

from tools.run.run_files import TELEMETRY_LOG
from tools.run.telemetry_log import CHUNK_BYTES, EVENT_CHANNELS, FIXED_CHANNELS, Chunk, LogDamage, iter_chunks
from tools.run.verdict import Bounds, judge
from gen.lib.one_line import one_line
from gen.lib.params import constant, default as param_default

# The controller's states as telemetry numbers them (the registry's, firmware/params/params.toml).
STATE_NAMES = dict(enumerate(constant("controller-states")))
STATE_RUNNING = constant("controller-states").index("running")
PAIRING_WINDOW = 4096  # periods: w_true and w_hat of one period are paired within this much of each other
# Channels whose sender publishes exactly one message per period, numbered from 0: step == seq.
ONE_PER_PERIOD = ("ARM_CTL", "ARM_TIMING", "ARM_SIM")


class PairwiseSum:
    """numpy's float64 np.add.reduce over a 1-D array of exactly n values (0 + pairwise
    summation: halves rounded down to a multiple of 8, blocks of at most 128 summed by numpy
    itself), fed in pieces of any size, so its result is bit for bit the whole array's sum
    without keeping the array. result() is None if the count fed is not n."""

    def __init__(self, n: int) -> None:
        self.n, self.count, self.total = n, 0, None
        self._pending: list[np.ndarray] = []
        self._have = 0
        self._gen = self._tree(n)
        self._need = next(self._gen) if n > 0 else 0

    @staticmethod
    def _tree(n: int):  # noqa: ANN205 - a coroutine: yields block lengths, is sent their sums
        if n <= 128:
            return (yield n)
        n2 = n // 2
        n2 -= n2 % 8
        left = yield from PairwiseSum._tree(n2)
        right = yield from PairwiseSum._tree(n - n2)
        return left + right

    def feed(self, x: np.ndarray) -> None:
        self.count += len(x)
        if self.total is not None or self.count > self.n or len(x) == 0:
            return
        self._pending.append(np.ascontiguousarray(x, dtype=np.float64))
        self._have += len(x)
        if self._have < self._need:
            return
        buf = np.concatenate(self._pending)
        at = 0
        while len(buf) - at >= self._need:
            s = np.add.reduce(buf[at:at + self._need])
            at += self._need
            try:
                self._need = self._gen.send(s)
            except StopIteration as done:
                self.total = np.float64(0.0) + done.value
                break
        self._pending = [buf[at:]]
        self._have = len(buf) - at

    def result(self) -> np.float64 | None:
        if self.n == 0 and self.count == 0:
            return np.float64(0.0)
        return self.total if self.count == self.n else None


class RowSum:
    """np.add.reduce(x, axis=0) of a 2-D array fed in row blocks: numpy adds the rows in order, so
    carrying the running sum as the first row of the next block gives the same bits."""

    def __init__(self) -> None:
        self.total: np.ndarray | None = None

    def feed(self, x: np.ndarray) -> None:
        if len(x) == 0:
            return
        self.total = np.add.reduce(x if self.total is None else np.concatenate([self.total[None], x]), axis=0)


class _Pairing:
    """w_true (ARM_SIM, by step) and w_hat (ARM_CTL running periods, by bus_period), paired by
    period in period order, the last message of a period winning, as a dict of the whole run
    would; a period is settled once both channels are PAIRING_WINDOW periods past it. A message
    for a period already settled is counted in `stale` and left out (only a foreign sender does
    that)."""

    def __init__(self) -> None:
        self.keys = [np.empty(0, np.int64), np.empty(0, np.int64)]  # hat, true
        self.rows: list[np.ndarray | None] = [None, None]
        self.settled = -(1 << 62)
        self.stale = 0
        self.count = 0
        self.sq_true, self.sq_err = RowSum(), RowSum()

    def add(self, side: int, keys: np.ndarray, rows: np.ndarray) -> None:
        fresh = keys > self.settled
        self.stale += int(len(keys) - fresh.sum())
        keys, rows = keys[fresh], rows[fresh]
        if self.rows[side] is not None:
            keys = np.concatenate([self.keys[side], keys])
            rows = np.concatenate([self.rows[side], rows])
        if len(keys) == 0:
            return
        # one row per period, the last one logged: np.unique of the reversed keys finds last occurrences
        rev_unique, rev_at = np.unique(keys[::-1], return_index=True)
        self.keys[side] = rev_unique
        self.rows[side] = rows[len(keys) - 1 - rev_at]

    def settle(self, upto: int | None = None) -> None:
        """Pair and accumulate the periods up to `upto` (all when None)."""
        if upto is None:
            upto = 1 << 62
        if self.rows[0] is None or self.rows[1] is None:
            if upto == 1 << 62:
                self.settled = upto
            return
        cut = [int(np.searchsorted(k, upto, side="right")) for k in self.keys]
        common, ih, it = np.intersect1d(self.keys[0][:cut[0]], self.keys[1][:cut[1]], assume_unique=True,
                                        return_indices=True)
        if len(common):
            wt = self.rows[1][it]
            wh = self.rows[0][ih]
            self.sq_true.feed(wt ** 2)
            self.sq_err.feed((wt - wh) ** 2)
            self.count += len(common)
        for side in (0, 1):
            self.keys[side] = self.keys[side][cut[side]:]
            self.rows[side] = self.rows[side][cut[side]:]  # type: ignore[index]
        self.settled = max(self.settled, upto)

    def feed_chunk_done(self, high: list[int]) -> None:
        # the channel behind sets the pace, unless it is more than 4 windows behind (it stopped):
        # then the other's periods are settled unpaired, so that memory stays bounded
        upto = max(min(high), max(high) - 4 * PAIRING_WINDOW) - PAIRING_WINDOW
        if upto > self.settled:
            self.settle(upto)


class _Sequences:
    """One channel's sequence numbers against what its sender says it sent: distinct ones in
    [0, sent) in a bit set (sent / 8 bytes), duplicates, and messages that cannot be the sender's
    (sequence number outside [0, sent), or a step that contradicts it)."""

    def __init__(self, sent: int | None, one_per_period: bool) -> None:
        self.sent = sent
        self.one_per_period = one_per_period
        self.bits = np.zeros((sent + 7) // 8 if sent else 0, np.uint8)
        self.logged = self.distinct = self.duplicates = self.beyond = self.contradicting = 0
        self.highest = -1

    def feed(self, seq: np.ndarray, step: np.ndarray | None) -> None:
        self.logged += len(seq)
        if self.sent is None or len(seq) == 0:
            return
        bad = (seq < 0) | (seq >= self.sent)
        self.beyond += int(bad.sum())
        if self.one_per_period and step is not None:
            contra = (step != seq) & ~bad
            self.contradicting += int(contra.sum())
            bad |= contra
        s = seq[~bad]
        if len(s) == 0:
            return
        u = np.unique(s)
        fresh = u[((self.bits[u >> 3] >> (u & 7).astype(np.uint8)) & 1) == 0]
        self.duplicates += int(len(s) - len(fresh))
        self.distinct += len(fresh)
        self.highest = max(self.highest, int(u[-1]))
        byte = fresh >> 3
        ub, first = np.unique(byte, return_index=True)
        self.bits[ub] |= np.bitwise_or.reduceat((1 << (fresh & 7)).astype(np.uint8), first)

    def accounting(self) -> dict[str, Any]:
        sent = self.sent or 0
        foreign = self.beyond + self.contradicting + self.duplicates
        return {"sent": sent, "logged": self.logged, "lost": sent - self.distinct,
                "sequence_gaps": self.highest + 1 - self.distinct,
                "duplicates": self.duplicates, "beyond_sent": self.beyond, "contradicting_step": self.contradicting,
                "logged_beyond_sent": max(0, self.logged - sent), "foreign": foreign}


class _AfterStop:
    """The arm's true motion after the stop (ARM_SIM): each joint's largest |q - q0| over the
    `periods` simulated periods from bus period `from_period` on, q0 its position as that period
    began (the truth of the period before it). Rows outside the window are not kept."""

    def __init__(self, from_period: int | None, periods: int) -> None:
        self.first = None if from_period is None else from_period - 1  # the truth the stop starts from
        self.last = None if from_period is None else from_period - 1 + periods
        self.steps: list[np.ndarray] = []
        self.q: list[np.ndarray] = []

    def feed(self, sim: np.ndarray) -> None:
        if self.first is None or len(sim) == 0:
            return
        keep = (sim["step"] >= self.first) & (sim["step"] <= self.last)
        if keep.any():
            self.steps.append(sim["step"][keep])
            self.q.append(sim["q"][keep].astype(np.float64))

    def result(self, period_s: float) -> dict[str, Any]:
        if self.first is None:
            return {}
        steps = np.concatenate(self.steps) if self.steps else np.empty(0, np.int64)
        at_start = np.nonzero(steps == self.first)[0]
        if len(at_start) == 0:
            return {"moved_after_stop_deg": None, "after_stop_covered_s": 0.0,
                    "after_stop_problem": f"no simulator truth for bus period {self.first} (the stop's start)"}
        q = np.concatenate(self.q)
        q0 = q[at_start[-1]]
        after = steps > self.first
        moved = np.degrees(np.abs(q[after] - q0).max(axis=0)) if after.any() else np.zeros(len(q0))
        covered = len(np.unique(steps[after])) * period_s
        return {"moved_after_stop_deg": moved.tolist(), "moved_after_stop_max_deg": float(moved.max()),
                "after_stop_covered_s": covered}


class LogScan:
    """One streaming pass over a run's log: the metrics of control_metrics, the telemetry
    accounting and the last controller state, in memory that does not grow with the run."""

    def __init__(self, hold_s: float, rate_hz: float, sent: dict[str, int], expected_periods: int,
                 stop_from: int | None = None, after_stop_periods: int = 0) -> None:
        self.after_stop = _AfterStop(stop_from, after_stop_periods)
        self.t_min = hold_s - 0.5 / rate_hz
        self.seqs = {ch: _Sequences(sent.get(ch), ch in ONE_PER_PERIOD) for ch in set(sent) | set(FIXED_CHANNELS)
                     | set(EVENT_CHANNELS)}
        self.undecodable = dict.fromkeys(self.seqs, 0)
        self.running = 0
        self.n_joints: int | None = None
        self.e_max: np.ndarray | None = None
        self.tau_max: np.ndarray | None = None
        self.e_sq = RowSum()
        self.saturated: np.ndarray | None = None
        self.expected = expected_periods
        self.power = PairwiseSum(expected_periods)
        self.tau_sq = PairwiseSum(expected_periods)
        self.pairing = _Pairing()
        self.high = [-(1 << 62), -(1 << 62)]
        self.last_state: int | None = None
        self.damage = LogDamage()  # where the log breaks, if it does
        self.power_total: np.float64 | None = None
        self.tau_sq_total: np.float64 | None = None

    def feed(self, chunk: Chunk) -> None:
        for ch, n in chunk.undecodable.items():
            self.undecodable[ch] = self.undecodable.get(ch, 0) + n
        for ch, arr in chunk.arrays.items():
            self.seqs[ch].feed(arr["seq"], arr["step"])
        for ch, evs in chunk.events.items():
            self.seqs[ch].feed(np.array([m.seq for m in evs], dtype=np.int64), None)
        ctl, sim = chunk.arrays["ARM_CTL"], chunk.arrays["ARM_SIM"]
        self.after_stop.feed(sim)
        if len(ctl):
            self.last_state = int(ctl["state"][-1])
        run = ctl[(ctl["state"] == STATE_RUNNING) & (ctl["t"] >= self.t_min)]
        if len(sim):
            self.pairing.add(1, sim["step"], sim["w_true"].astype(np.float64))
            self.high[1] = max(self.high[1], int(sim["step"].max()))
        if len(run):
            e = run["e"].astype(np.float64)
            tau = run["tau"].astype(np.float64)
            qd = run["qd"].astype(np.float64)
            self.running += len(run)
            self.n_joints = e.shape[1]
            em, tm = np.abs(e).max(axis=0), np.abs(tau).max(axis=0)
            self.e_max = em if self.e_max is None else np.maximum(self.e_max, em)
            self.tau_max = tm if self.tau_max is None else np.maximum(self.tau_max, tm)
            self.e_sq.feed(e ** 2)
            self.power.feed(np.abs(tau * qd).sum(axis=1))
            self.tau_sq.feed((tau ** 2).sum(axis=1))
            bits = (run["saturated_mask"][:, None] >> np.arange(e.shape[1])) & 1
            sat = bits.sum(axis=0, dtype=np.int64)
            self.saturated = sat if self.saturated is None else self.saturated + sat
            self.pairing.add(0, run["bus_period"], run["w_hat"].astype(np.float64))
            self.high[0] = max(self.high[0], int(run["bus_period"].max()))
        self.pairing.feed_chunk_done(self.high)

    def finish(self) -> None:
        self.pairing.settle()


def _power_sums(chunks: Iterable[Chunk], t_min: float, n: int) -> tuple[np.float64 | None, np.float64 | None]:
    """The two per-period means' sums again, now that the count of running periods is known."""
    power, tau_sq = PairwiseSum(n), PairwiseSum(n)
    for chunk in chunks:
        ctl = chunk.arrays["ARM_CTL"]
        run = ctl[(ctl["state"] == STATE_RUNNING) & (ctl["t"] >= t_min)]
        tau, qd = run["tau"].astype(np.float64), run["qd"].astype(np.float64)
        power.feed(np.abs(tau * qd).sum(axis=1))
        tau_sq.feed((tau ** 2).sum(axis=1))
    return power.result(), tau_sq.result()


def scan_log(path: Path, hold_s: float, rate_hz: float, sent: dict[str, int], expected_periods: int,
             chunk_bytes: int = CHUNK_BYTES, stop_from: int | None = None, after_stop_periods: int = 0) -> LogScan:
    """Stream the log once (twice when the running periods are not the expected count: the two
    pairwise-summed means need the count before they start)."""
    scan = LogScan(hold_s, rate_hz, sent, max(int(expected_periods), 0), stop_from, after_stop_periods)
    if path.exists():
        for chunk in iter_chunks(path, chunk_bytes, scan.damage):
            scan.feed(chunk)
    scan.finish()
    if scan.running and scan.running != scan.expected:
        scan.power_total, scan.tau_sq_total = _power_sums(iter_chunks(path, chunk_bytes), scan.t_min, scan.running)
    else:
        scan.power_total, scan.tau_sq_total = scan.power.result(), scan.tau_sq.result()
    return scan


def _rms(sum_sq: np.ndarray | None, n: int) -> list[float]:
    return np.sqrt(sum_sq / n).tolist() if n else []


def control_metrics(scan: LogScan) -> dict[str, Any]:
    """Over the trajectory: running periods after the start-pose hold (t is the period's time as
    the controller logged it, float32: compared within half a period)."""
    n = scan.running
    if not n:
        return {"periods_running": 0}
    mean_sq = scan.e_sq.total / n
    out: dict[str, Any] = {
        "periods_running": n,
        "tracking_max_abs_rad": scan.e_max.tolist(),
        "tracking_rms_rad": np.sqrt(mean_sq).tolist(),
        "tracking_max_abs_deg": np.degrees(scan.e_max).tolist(),
        "tracking_rms_deg": np.degrees(np.sqrt(mean_sq)).tolist(),
        "max_abs_torque_nm": scan.tau_max.tolist(),
        # Mechanical power the joints deliver, |tau . qd| summed over joints, averaged in time.
        "torque_power_w": float(scan.power_total / n),
        "mean_sum_tau_squared_nm2": float(scan.tau_sq_total / n),
        "saturated_fraction": [float(np.float64(c) / n) for c in scan.saturated.tolist()],
    }
    p = scan.pairing
    if p.count:
        out["w_rms"] = _rms(p.sq_true.total, p.count)
        out["estimation_error_rms"] = _rms(p.sq_err.total, p.count)
        out["estimation_periods"] = p.count
    return out


def telemetry_accounting(scan: LogScan, sent: dict[str, int]) -> dict[str, Any]:
    """Per channel: sent (the sender's count), logged, lost (sent sequence numbers never logged),
    sequence gaps, and what no sender of this run logged: duplicate sequence numbers, numbers at
    or beyond what the sender sent, steps that contradict their number (channels with one message
    per period number them by period), messages logged beyond those sent, and their sum `foreign`."""
    out: dict[str, Any] = {}
    for ch in sent:
        acct = scan.seqs[ch].accounting()
        acct["undecodable"] = scan.undecodable.get(ch, 0)
        out[ch] = acct
    return out


def foreign_telemetry(tele: dict[str, Any]) -> list[str]:
    """What in the log cannot come from the run's own senders, per channel, for the verdict."""
    out = []
    for ch, a in tele.items():
        what = [f"{a[k]} {label}" for k, label in (("logged_beyond_sent", "logged beyond the sent"),
                                                   ("duplicates", "duplicate sequence numbers"),
                                                   ("beyond_sent", "with sequence numbers at or beyond the sent"),
                                                   ("contradicting_step", "with a step that contradicts the sequence number"))
                if a.get(k)]
        if what:
            out.append(f"{ch}: {', '.join(what)} (of {a['logged']} logged, {a['sent']} sent)")
    return out


def stop_period(controller: dict[str, Any], sim: dict[str, Any]) -> tuple[int | None, str]:
    """The bus period the stop began: the controller's own record of it, or the period after the
    last one the simulator ran for the controller, whichever came first (a controller that died
    says nothing; a simulator stopped by a signal cut the drives' supply before the controller
    noticed)."""
    stop = controller.get("stop") or {}
    post = sim.get("post_stop") or {}
    found = []
    if stop.get("cause") not in (None, "none"):
        found.append((int(stop["from_bus_period"]), "controller"))
    if post.get("periods"):
        found.append((int(post["from_step"]), "simulator"))
    return min(found) if found else (None, "none")


def stop_record(controller: dict[str, Any], sim: dict[str, Any], stop_from: int | None, source: str,
                window_s: float, motion: dict[str, Any]) -> dict[str, Any]:
    """How the run's stop went: what began it and when, the safe state the controller reached (its
    ARM_EVENT and summary), what the drives ended in after the simulator ran the arm on, and each
    joint's true motion in the window after the stop (ARM_SIM)."""
    stop = controller.get("stop") or {}
    post = sim.get("post_stop") or {}
    return {"cause": stop.get("cause") if source == "controller" else post.get("why") if source == "simulator" else None,
            "from_bus_period": stop_from, "found_by": source, "safe_state": stop.get("safe_state"),
            "braked": stop.get("braked"), "window_s": window_s,
            "simulator": {"why": post.get("why"), "braked": post.get("braked"),
                          "statuswords": post.get("statuswords"), "from_step": post.get("from_step"),
                          "moved_deg": post.get("moved_deg")} if post else None,
            **motion}


def lateness_record(controller: dict[str, Any], sim: dict[str, Any], stop_from: int | None) -> dict[str, Any]:
    """Which side was late, from both ends (wall-clock facts: environment, not results): the
    controller's count of the periods that missed their states by side and its account of a stop for
    lateness (firmware/port/linux/lateness.c), and the simulator's own times for each SYNC it
    answered, those of the periods before the stop beside them."""
    late = controller.get("lateness") or {}
    answers = sim.get("answer_timing") or {}
    near = [{"period": p, "read_us": r, "answered_us": a} for p, r, a in answers.get("last", [])
            if stop_from is not None and stop_from - 8 <= p < stop_from]
    return {"late_periods": late.get("late_periods"), "worst_us": late.get("worst_us"),
            "stop_side": late.get("stop_side"), "stop": late.get("stop") or None,
            "simulator": {k: answers.get(k) for k in ("n", "read_p99_us", "read_max_us", "answer_p50_us",
                                                      "answer_p99_us", "answer_max_us")} if answers else None,
            "simulator_before_stop": near}


def final_state(scan: LogScan, controller: dict[str, Any]) -> str:
    if controller.get("final_state"):
        return str(controller["final_state"])
    return STATE_NAMES.get(scan.last_state, "?") if scan.last_state is not None else "unknown"


def analyse(out_dir: Path, controller: dict[str, Any], sim: dict[str, Any], config: dict[str, Any],
            environment: dict[str, Any], bounds: Bounds | None = None) -> dict[str, Any]:
    """run.json. config: the run's settings, with ref_hold_s and rate_hz the controller was given
    (a controller that died wrote no summary: these still say what the run was asked for)."""
    bounds = bounds or Bounds()
    sent = dict(controller.get("telemetry", {}).get("sent", {}))
    sent.update(sim.get("telemetry_sent", {}))
    problems = [s for s in (controller.get("reason"), sim.get("reason")) if s]
    hold = float(controller.get("ref_hold_s", config.get("ref_hold_s", 0.0)))
    rate = float(controller.get("rate_hz", config.get("rate_hz", param_default("controller", "rate"))))
    requested = controller.get("steps_requested", round((config["duration_s"] + hold) * rate))
    stop_from, stop_source = stop_period(controller, sim)
    window_s = float((sim.get("post_stop") or {}).get("configured_s") or param_default("simulator", "post-stop"))
    scan = scan_log(out_dir / TELEMETRY_LOG, hold, rate, sent, requested - round(hold * rate),
                    stop_from=stop_from, after_stop_periods=round(window_s * rate))
    tele = telemetry_accounting(scan, sent) if sent else {}
    results = {
        **config,
        "problems": problems,
        "final_state": final_state(scan, controller),
        "final_fault": controller.get("final_fault", "unknown"),
        # None where the process that knows died without saying: unknown, not zero
        "steps": controller.get("steps_done"),
        "steps_requested": requested,
        "trajectory_periods": requested - round(hold * rate),
        "simulated_periods": sim.get("periods"),
        "controller_bus_periods": controller.get("bus_periods"),
        "commands_missed": sim.get("commands_missed"),
        "commands_late": sim.get("commands_late"),
        "drive_faults": sim.get("drive_faults"),
        "ref_hold_s": hold,
        "design_hash": controller.get("design_hash", ""),
        **control_metrics(scan),
        "stop": stop_record(controller, sim, stop_from, stop_source, window_s, scan.after_stop.result(1.0 / rate)),
    }
    transport = {
        "controller_frames": controller.get("frames", {}),
        "simulator_frames": {k: sim.get(k) for k in ("frames_tx", "frames_rx", "tx_dropped", "rx_foreign_drive",
                                                     "rx_unknown_id", "rx_bad_frame", "rx_undecodable",
                                                     "rx_kernel_drops", "rx_wrong_bus", "rx_duplicate_command",
                                                     "rx_sync_out_of_sequence")},
        "overruns": controller.get("overruns"),
        "bus_timing": sim.get("bus_timing", []),
        "telemetry": tele,
        "telemetry_lost_total": int(sum(v["lost"] for v in tele.values())) if tele else None,
        "telemetry_gaps_total": int(sum(v["sequence_gaps"] for v in tele.values())) if tele else None,
        "telemetry_foreign": foreign_telemetry(tele),
        # where the log breaks and what was left unread (a damaged log: the run is incomplete, never ok)
        "telemetry_log": scan.damage.as_dict(),
    }
    environment = {**environment, "lateness": lateness_record(controller, sim, stop_from)}
    verdict, reasons = judge(results, transport, controller, sim, environment.get("exit_codes", {}), bounds)
    results["result"] = verdict
    results["verdict_reasons"] = reasons
    results["bounds"] = bounds.as_dict()
    return {"results": results, "transport": transport, "environment": environment}


def table(run: dict[str, Any]) -> str:
    r, t, env = run["results"], run["transport"], run["environment"]
    names = r.get("joint_names") or [f"joint{i + 1}" for i in range(len(r.get("tracking_max_abs_deg", [])))]
    lines = [f"{'joint':<14}{'max |e| (deg)':>15}{'RMS e (deg)':>14}{'RMS w-w_hat':>14}"]
    for i, name in enumerate(names[: len(r.get("tracking_max_abs_deg", []))]):
        est = r.get("estimation_error_rms")
        est_s = f"{est[i]:>14.4f}" if est else f"{'-':>14}"
        lines.append(f"{one_line(name):<14}{r['tracking_max_abs_deg'][i]:>15.4f}{r['tracking_rms_deg'][i]:>14.4f}{est_s}")
    # a run whose controller died has no final state nor step count: its result says so
    lines.append(f"result {r['result']}: method {r.get('method', '?')}, controller {r.get('final_state', 'unknown')} "
                 f"after {r.get('steps', '?')} of {r.get('steps_requested', '?')} periods")
    for why in r.get("verdict_reasons", []):
        lines.append(f"  {one_line(why)}")
    stop = r.get("stop") or {}
    if stop.get("from_bus_period") is not None:
        moved = stop.get("moved_after_stop_deg")
        how = (f"at most {max(moved):.3f} deg of motion in the {stop.get('after_stop_covered_s', 0):.1f} s after it "
               f"(joint {1 + moved.index(max(moved))})" if moved else stop.get("after_stop_problem", "motion unknown"))
        lines.append(f"stop ({stop.get('cause')}, bus period {stop['from_bus_period']}): "
                     f"{stop.get('safe_state') or 'no safe state reported'}; {how}")
    cf, sf = t["controller_frames"], t["simulator_frames"]
    lines.append(f"frames: controller sent {cf.get('tx', '?')} / received {cf.get('rx', '?')}, "
                 f"simulator sent {sf['frames_tx']} / received {sf['frames_rx']}")
    if t["telemetry"]:
        sent = sum(v["sent"] for v in t["telemetry"].values())
        logged = sum(v["logged"] for v in t["telemetry"].values())
        foreign = sum(v.get("foreign", 0) for v in t["telemetry"].values())
        lines.append(f"telemetry: {sent} messages sent, {logged} logged, {t['telemetry_lost_total']} lost"
                     + (f", {foreign} foreign" if foreign else ""))
    else:
        lines.append("telemetry: unknown (no process said what it sent)")
    for b in t.get("bus_timing", []):
        lines.append(f"bus timing ({r.get('bus_timing', '?')}), bus {b['bus']} ({b['phy']}, drives "
                     f"{','.join(map(str, b['drives']))}): SYNC -> last command {b['sync_to_last_cmd_mean_us']:.1f} us "
                     f"mean, {b['sync_to_last_cmd_max_us']:.1f} us max; {b['commands_late']} commands late")
    if env.get("realtime_factor"):
        cost = env.get("simulator_period_cost_us") or {}
        lines.append(f"wall time {env['wall_s']:.1f} s; after boot the simulation ran at {env['realtime_factor']:.1f}x "
                     f"real time (simulator CPU per period p50 {cost.get('p50', '?')} us, p99 {cost.get('p99', '?')} us)")
    return "\n".join(lines)
