"""armctl docs: every generated figure of README.md and docs/ rendered from its results file.

A page marks a region `<!-- numbers:NAME (...) -->` ... `<!-- /numbers:NAME -->`; RENDERERS says
which results file and which function make NAME's text. The results files are written by the
commands themselves with `--record` (docs/results/*.json: `bench`, `timing`, `faults`, `test`;
tools/bench/record.py) and by `study --record` and `tune` (tools/studies/). Each region ends by
naming the command that made its figures, the machine and the date. `--check` renders every region
and exits 1 if a page differs (tests/python/test_docs.py runs it), so no figure can be typed by hand
or drift from its file."""

from __future__ import annotations

import argparse
import math
import json
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

from gen.lib.atomic_output import write_text_atomic
from gen.lib.escape import markdown_code as code, markdown_fence, markdown_text as md
from gen.lib.paths import DOCS, DOCS_RESULTS, REPO
from tools.commands import CommandError

STUDIES = REPO / "tools" / "studies"
REGION = re.compile(r"(<!-- numbers:(?P<name>[a-z0-9-]+)\b[^>]*-->\n)(?P<body>.*?)(<!-- /numbers:(?P=name) -->)", re.S)


class DocsError(CommandError):
    """A region without a renderer, or a results file that is missing or lacks what a region needs."""


def pages() -> list[Path]:
    return [REPO / "README.md", *sorted(DOCS.rglob("*.md"))]


def _load(path: Path, how: str) -> dict[str, Any]:
    try:
        return json.loads(path.read_text())
    except FileNotFoundError:
        raise DocsError(f"{path.relative_to(REPO)} is missing: {how} writes it") from None
    except ValueError as exc:
        raise DocsError(f"{path.relative_to(REPO)}: not JSON ({exc}); {how} writes it again") from None


RECORDED_BY = {"bench-step": "tools/armctl bench step --record", "bench-synth": "tools/armctl bench synth --record",
               "bench-sim": "tools/armctl bench sim --record", "bench-study": "tools/armctl bench study --record",
               "timing": "tools/armctl timing --record", "faults": "tools/armctl faults --record",
               "timing-repeat": "tools/armctl timing --repeat 20 --record",
               "test": "tools/armctl test --record", "bench-pil": "tools/armctl bench pil --record"}


def _result(name: str) -> dict[str, Any]:
    return _load(DOCS_RESULTS / f"{name}.json", RECORDED_BY[name])


def _made_by(r: dict[str, Any]) -> str:
    """Which command, on what machine and when: the line under every rendered figure."""
    rec = r["recorded"]
    m = rec["machine"]
    kind = "virtual machine" if m.get("virtual") else "machine"
    commit = (rec.get("commit") or "?")[:10] + (" with local changes" if rec.get("dirty") else "")
    return (f"*{code(rec['command'])}, {rec['date_utc'][:10]}, on a {m['cores']}-core {kind} ({md(m['cpu'])}, "
            f"{m['memory_gib']} GiB, {md(m['os'])}, Linux {m['kernel']}; load average {m['load_average_1min']} at "
            f"the start), code {md(commit)}.*")


def _block(text: str) -> str:
    return markdown_fence(text.splitlines())


def bench_step(r: dict[str, Any]) -> str:
    from tools.bench import table

    return _block(table(r)) + "\n\n" + _made_by(r)


def rnea(r: dict[str, Any]) -> str:
    n = r["rnea"]["instructions"]
    pm = r["methods"]["pm"]["float"]
    return (f"Pinocchio's RNEA takes {n['pinocchio-double']:,.0f} instructions in double and "
            f"{n['pinocchio-float']:,.0f} in float; the arm's generated kernel takes **{n['kernel']:,.0f}: "
            f"{r['rnea']['pinocchio_double_over_kernel']:.1f}x fewer than Pinocchio in double**, our general "
            f"`arm_rnea` {n['ours']:,.0f}, and the *whole* PM step (IDC, estimator, controller, safety checks: "
            f"{pm:,.0f}) takes {r['rnea']['pm_step_over_pinocchio_double_rnea']:.2f} of Pinocchio's RNEA alone.\n\n"
            + _made_by(r))


def memory(r: dict[str, Any]) -> str:
    rows = ["| image | flash | RAM | worst-case stack |", "|---|---|---|---|"]
    for preset, c in r.get("cortex_m", {}).items():
        if not isinstance(c, dict) or "memory" not in c:
            continue
        m = c["memory"]
        rows.append(f"| {preset} ({m['part']}) | {m['flash_bytes'] / 1024:.1f} of {m['flash_budget'] / 1024:.0f} KiB | "
                    f"{m['ram_bytes'] / 1024:.1f} of {m['ram_budget'] / 1024:.0f} KiB | "
                    f"{m['stack_worst_case_bytes']} of {m['stack_budget']} B |")
    if len(rows) == 2:
        raise DocsError("docs/results/bench-step.json has no Cortex-M memory report: run tools/armctl bench step "
                        "--record with the cross toolchain installed")
    return "\n".join(rows) + "\n\n" + _made_by(r)


def synth(r: dict[str, Any]) -> str:
    rows = ["| solved | estimator gamma: optimal, design, verified | controller gamma (optimal) | synthesis, "
            "verification and emission |", "|---|---|---|---|"]
    for s in r["synth_n6"]:
        what = "per joint (what `synth` does here)" if s["mode"] == "per_joint" else "as one coupled problem"
        rows.append(f"| {what} | {s['estimator_gamma_opt']:.6f}, {s['estimator_gamma_design']:.6f}, "
                    f"{s['estimator_verified_hinf_norm']:.6f} | {s['controller_gamma_opt']:.3g} | "
                    f"{s['wall_time_median_s']:.2f} s (median of {s['repeats']}) |")
    return ("The paper's design, six joints, in the process (imports excluded):\n\n" + "\n".join(rows) + "\n\n"
            + _made_by(r))


def bench_sim(r: dict[str, Any]) -> str:
    from tools.bench import sim_table

    b = r["lockstep_udp"]["breakdown_us_per_period"]
    kernel = (b["bus_tx"] + b["bus_rx"]) / b["total"]
    return (_block(sim_table(r)) + f"\n\nOver UDP, {100 * kernel:.0f} % of the simulator's period is the kernel "
            "moving datagrams (`bus_tx`, `bus_rx`).\n\n" + _made_by(r))


def pil(r: dict[str, Any]) -> str:
    from tools.bench.pil import render

    return render(r) + "\n\n" + _made_by(r)


def bench_study(r: dict[str, Any]) -> str:
    from tools.bench.study import table

    return _block(table(r)) + "\n\n" + _made_by(r)


def timing(r: dict[str, Any]) -> str:
    from tools.bench.timing import table

    verdict = r["verdict"] + (f": {r['verdict_reason']}" if r.get("verdict_reason") else "")
    return _block(table(r)) + f"\n\nVerdict: {code(verdict)}.\n\n" + _made_by(r)


def timing_repeat(r: dict[str, Any]) -> str:
    from tools.bench.timing_repeat import table

    return _block(table(r)) + "\n\n" + _made_by(r)


def faults(r: dict[str, Any]) -> str:
    from tools.bench.faults import table

    return _block(table(r["rows"])) + "\n\n" + _made_by(r)


def _minutes(s: float) -> str:
    whole = round(s)  # rounded first: 839.7 s is 14 min 0 s, never 13 min 60 s
    return f"{whole // 60} min {whole % 60} s" if whole >= 60 else f"{whole} s"


def test_time(r: dict[str, Any]) -> str:
    if not r:
        return ("No run of the whole suite is recorded yet: `tools/armctl test --record` records one (the whole "
                "suite, every test passed).")
    rows = ["| phase | wall time |", "|---|---|"]
    rows += [f"| {phase} | {_minutes(s)} |" for phase, s in r["phases_s"].items()]
    rows.append(f"| **the whole suite** | **{_minutes(r['wall_s'])}** |")
    return (f"On {r['workers']} pytest worker(s)" + (", strict (no test may skip)" if r.get("strict") else "")
            + ":\n\n" + "\n".join(rows) + "\n\n" + _made_by(r))


def headline_table(record: dict[str, Any]) -> str:
    from tools.study.headline import render

    return render(record) + "\n\n" + _study_made_by(record)


def _study_made_by(record: dict[str, Any]) -> str:
    return (f"*`tools/armctl study --record`: {len(record['seeds'])} seeds, {record['duration_s']:g} s trajectory, "
            f"the bundled arm ({md(record['arm']['name'])}), code identity {md(record['code'])}.*")


def findings(record: dict[str, Any]) -> str:
    from tools.study.report import _claims, _labels, _verdict

    out = []
    for name, sc in record["scenarios"].items():
        if not sc.get("pm_versus"):
            raise DocsError("tools/studies/paper.headline.json keeps no comparisons: tools/armctl study --record "
                            "writes them")
        out += [f"**{md(name)}**", "", *_claims(sc), *_verdict(record, sc, _labels(record, False)), ""]
    return "\n".join(out) + "\n" + _study_made_by(record)


def answer(record: dict[str, Any]) -> str:
    """The study's answer in plain words (the report's opening: tools/study/answer.py)."""
    from tools.study.answer import answer as words

    return "\n".join(words(record)) + "\n\n" + _study_made_by(record)


def picks(record: dict[str, Any]) -> str:
    """What to pick for the bundled arm, per scenario, in words (the report's)."""
    from tools.study.report import recommendation

    return "\n".join(recommendation(record, name) for name in record["scenarios"]) + "\n\n" + _study_made_by(record)


def resonances(record: dict[str, Any]) -> str:
    """The bundled arm's drive train and each joint's first resonance (the report's table)."""
    from tools.study.report import drivetrain_table

    return drivetrain_table(record) + "\n\n" + _study_made_by(record)


def protocols(record: dict[str, Any]) -> str:
    """The headline (CiA 402) beside the same picks over the arm protocol: the sum over joints of
    the mean L-infinity tracking error per scenario and method."""
    from tools.study.headline import RECORD_BY_PROTOCOL

    other = _load(RECORD_BY_PROTOCOL["arm"], "tools/armctl study --protocol arm --record")
    rows = ["| scenario | method | CiA 402: sum of joints' L-inf e (deg) | arm protocol | CiA 402 / arm |",
            "|---|---|---|---|---|"]
    for name, sc in record["scenarios"].items():
        for m in record["methods"]:
            a = sc["stats"][m]["linf"]["total"]["mean"]
            b = other["scenarios"].get(name, {}).get("stats", {}).get(m, {}).get("linf", {}).get("total", {}).get("mean")
            cell = (lambda v: f"{math.degrees(v):.3f}" if v is not None else "-")
            ratio = f"{a / b:.2f}" if a is not None and b else "-"
            ends = sc["stats"][m]["results"]
            note = "" if all(r == "ok" for r in ends) else f" ({sum(r != 'ok' for r in ends)} not ok)"
            rows.append(f"| {md(name)} | {md(m)} | {cell(a)}{note} | {cell(b)} | {ratio} |")
    return "\n".join(rows) + "\n\n" + _study_made_by(record) + " " + _study_made_by(other).replace(
        "study --record", "study --protocol arm --record")


def tuning(record: dict[str, Any]) -> str:
    pairs = [(s, m, r) for s, methods in record["scenarios"].items() for m, r in methods.items()]
    converged = sum(r.get("status") == "converged" for _, _, r in pairs)
    trials = [r["trials_run"] for _, _, r in pairs]
    methods = list(dict.fromkeys(m for _, m, _ in pairs))
    rows = ["| method | " + " | ".join(map(md, record["scenarios"])) + " |", "|---|" + "---|" * len(record["scenarios"])]
    for m in methods:
        cells = [f"{md(str(r['status']))}, {r['trials_run']} trials" if (r := record["scenarios"][s].get(m)) else "-"
                 for s in record["scenarios"]]
        rows.append(f"| {md(m)} | " + " | ".join(cells) + " |")
    caps = sorted({r["cap"] for _, _, r in pairs})
    held = [(s, m, r) for s, m, r in pairs if (r.get("validation") or {}).get("picked_rank") is not None]
    not_held = [f"{md(m)} in {md(s)}" for s, m, r in pairs if (r.get("validation") or {}).get("picked_rank") is None]
    robust = (f" {len(held)} of {len(pairs)} picks ran ok on every validation seed and robust corner"
              + (f" (the best by objective in {sum(r['validation']['picked_rank'] == 0 for _, _, r in held)}, the next "
                 "best in the others)" if held else "")
              + (f"; none of the candidates of {', '.join(not_held)} held, and its kept pick is not robust" if not_held
                 else "") + ".")
    t = record.get("last_tuning")
    took = (f" The last `tools/armctl tune` tuned {t['pairs']} pairs, {t['trials']} trials, in {_minutes(t['wall_s'])} "
            f"on {t['cpus']} cores (--jobs {t['jobs']}), {t['when'][:10]}." if t else "")
    return (f"{converged} of {len(pairs)} method-scenario pairs converged (the best improved by no more than "
            f"{100 * pairs[0][2]['tolerance']:g} % over the last {pairs[0][2]['plateau']} trials) within the cap of "
            f"{', '.join(str(c) for c in caps)} trials, the same for every method: {sum(trials)} trials, "
            f"{min(trials)}-{max(trials)} a pair.{robust}{took}\n\n" + "\n".join(rows) + "\n\n"
            "*`tools/armctl tune` (`tools/studies/paper.tuning.json`).*")


def _bus_facts() -> dict[str, Any]:
    """What the bus-load figures are computed from: the bundled drive table's PDO transmission
    types and the arm protocol's wiring (firmware/protocol/drives.toml, buses.toml), the budget and
    the heartbeat period (the parameter registry)."""
    from gen import drives as drives_mod
    from gen.lib import busload
    from gen.lib.params import constant

    return {"every": drives_mod.load_transmission(drives_mod.DEFAULT_DRIVES), "budget": constant("bus-budget"),
            "heartbeat_ms": constant("heartbeat-ms"), "topology": busload.load_topology(busload.DEFAULT_TOPOLOGY)}


def bus_load(f: dict[str, Any]) -> str:
    """The worst-case load of CiA 402 drives per bus (gen/lib/busload.py, as `armctl busload`
    computes it), the wiring the bundled arm gets, and the arm protocol's load on its wiring."""
    from gen.lib import busload as bl
    from gen.lib.params import default

    rate = default("controller", "rate")
    fd = bl.Bus("can0", True, 1e6, 5e6, [])
    every, hb, budget = f["every"], f["heartbeat_ms"], f["budget"]
    tpdo2 = every.get("tpdo2", 1)
    counts = (1, 2, 3, 6)
    rows = ["| bus | TPDO2 | " + " / ".join(map(str, counts)) + f" drives at {rate:g} Hz | at {rate / 2:g} Hz | "
            f"drives a bus carries within {budget:.0%} at {rate:g} / {rate / 2:g} Hz |", "|---|---|---|---|---|"]
    for bus, what in ((bl.CLASSIC_1M, "classic 1 Mbit/s"), (fd, "CAN FD 1/5 Mbit/s")):
        for ev, when in (({}, "every SYNC"), (every, f"every {tpdo2}nd SYNC (the bundled drive table's)")):
            if ev is every and tpdo2 == 1:
                continue
            cells = [" / ".join(f"{100 * bl.canopen_load(bus, n, r, hb, ev):.1f}" for n in counts) + " %"
                     for r in (rate, rate / 2)]
            fit = " / ".join(str(bl.canopen_drives_per_bus(bus, r, budget, hb, ev)) for r in (rate, rate / 2))
            rows.append(f"| {what} | {when} | {cells[0]} | {cells[1]} | {fit} |")
    wiring = bl.canopen_wiring(6, rate, every, budget, hb)
    six = ("six drives need more than the controller's "
           f"{bl.MAX_BUSES} classic buses" if wiring is None else
           f"{len(wiring)} classic 1 Mbit/s buses (" + ", ".join(
               f"drives {bl.drives_arg(b)}: {100 * bl.canopen_load(b, len(b.drives), rate, hb, every):.1f} %"
               for b in wiring) + ")")
    arm = bl.compute(f["topology"], rate, hb, bl.default_protocol(), 6)
    one_fd = bl.compute([bl.Bus("can0", True, 1e6, 5e6, list(range(1, 7)))], rate, hb, bl.default_protocol(), 6)[0]
    return ("\n".join(rows) + f"\n\nThe bundled arm's six drives at {rate:g} Hz with its drive table: {six}. The arm "
            f"protocol's frames on its wiring (`firmware/protocol/buses.toml`): "
            + ", ".join(f"{x.bus.name} (drives {bl.drives_arg(x.bus)}) {100 * x.load:.1f} %, up to "
                        f"{math.floor(x.max_rate_hz(budget))} Hz" for x in arm)
            + f"; all six on one CAN FD 1/5 Mbit/s bus {100 * one_fd.load:.1f} %, up to "
              f"{math.floor(one_fd.max_rate_hz(budget))} Hz.\n\n"
            "*Computed by `gen/lib/busload.py`, as `tools/armctl busload` computes it, from "
            "`firmware/protocol/drives.toml` and `firmware/protocol/buses.toml`.*")


# NAME -> (the results file's loader, the renderer)
RENDERERS: dict[str, tuple[Callable[[], dict[str, Any]], Callable[[dict[str, Any]], str]]] = {
    "bench-step": (lambda: _result("bench-step"), bench_step),
    "rnea": (lambda: _result("bench-step"), rnea),
    "memory": (lambda: _result("bench-step"), memory),
    "synth": (lambda: _result("bench-synth"), synth),
    "bench-sim": (lambda: _result("bench-sim"), bench_sim),
    "bench-study": (lambda: _result("bench-study"), bench_study),
    "pil": (lambda: _result("bench-pil"), pil),
    "timing": (lambda: _result("timing"), timing),
    "timing-repeat": (lambda: _result("timing-repeat"), timing_repeat),
    "faults": (lambda: _result("faults"), faults),
    "test-time": (lambda: _result("test") if (DOCS_RESULTS / "test.json").is_file() else {}, test_time),
    "headline": (lambda: _load(STUDIES / "paper.headline.json", "tools/armctl study --record"), headline_table),
    "findings": (lambda: _load(STUDIES / "paper.headline.json", "tools/armctl study --record"), findings),
    "tuning": (lambda: _load(STUDIES / "paper.tuning.json", "tools/armctl tune"), tuning),
    "bus-load": (_bus_facts, bus_load),
    "answer": (lambda: _load(STUDIES / "paper.headline.json", "tools/armctl study --record"), answer),
    "picks": (lambda: _load(STUDIES / "paper.headline.json", "tools/armctl study --record"), picks),
    "resonances": (lambda: _load(STUDIES / "paper.headline.json", "tools/armctl study --record"), resonances),
    "protocols": (lambda: _load(STUDIES / "paper.headline.json", "tools/armctl study --record"), protocols),
}


def rendered(text: str, where: str, skipped: list[str] | None = None, done: list[str] | None = None) -> str:
    """text with every numbers region rendered from its results file. With `skipped`, a region that
    cannot be rendered keeps its text and its error is added there; without, it raises DocsError.
    `done`: each region rendered is added there ("page: name")."""
    def one(m: re.Match[str]) -> str:
        name = m.group("name")
        try:
            if name not in RENDERERS:
                raise DocsError(f"<!-- numbers:{name} -->: no such region (tools/commands/docs.py RENDERERS)")
            load, render_region = RENDERERS[name]
            try:
                body = render_region(load())
            except KeyError as exc:
                raise DocsError(f"numbers:{name}: its results file has no {exc}: record it again") from None
        except DocsError as exc:
            if skipped is None:
                raise DocsError(f"{where}: {exc}") from None
            skipped.append(f"{where}: {exc}")
            return m.group(0)
        if done is not None:
            done.append(f"{where}: {name}")
        return f"{m.group(1)}{body}\n{m.group(4)}"

    return REGION.sub(one, text)


def render(check: bool = False, skipped: list[str] | None = None, done: list[str] | None = None) -> list[Path]:
    """Render every page's regions; the pages that differed (written unless check). `skipped`,
    `done`: as for rendered()."""
    changed = []
    for page in pages():
        text = page.read_text()
        new = rendered(text, str(page.relative_to(REPO)), skipped, done)
        if new != text:
            changed.append(page)
            if not check:
                write_text_atomic(page, new)
    for page in changed:
        print(f"armctl docs: {page.relative_to(REPO)}: " + ("differs from its results files" if check else "rendered"))
    return changed


def add_subparser(sub: argparse._SubParsersAction) -> None:
    d = sub.add_parser("docs", help="render every generated figure of README.md and docs/ from its results file")
    d.add_argument("--check", action="store_true", help="change nothing; exit 1 if a page differs")
    d.set_defaults(run=run)


def run(ns: argparse.Namespace) -> int:
    done: list[str] = []
    changed = render(check=ns.check, done=done)
    if ns.check and changed:
        raise DocsError(f"{len(changed)} page(s) differ from their results files: tools/armctl docs renders them")
    pages_done = sorted({d.split(": ")[0] for d in done})
    print(f"armctl docs: {len(done)} region(s) on {len(pages_done)} page(s) "
          + ("rendered from their results files, each as it stands" if ns.check else "rendered") + ": "
          + ", ".join(pages_done))
    return 0
