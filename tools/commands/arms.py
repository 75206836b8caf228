"""armctl arms: the compatibility matrix (tools/bench/arms.py): every serial arm of the public model
sets in tools/bench/model_sets.toml through import, build and a 3 s software-in-the-loop run with
its default design, into runs/bench/arms.json, rendered into docs/arm-compatibility.md.

A benchmark, not a test: it installs each set on first use (its model files only, into
build/model-sets/) and takes about half a minute an arm. --sets runs some sets again and keeps the
other sets' rows; --list only shows what it would run. --path DIR runs the same matrix over every
MJCF and URDF under a folder (a clone of a model collection: mujoco_menagerie, robot_descriptions'
repositories), into runs/arms-NAME/ (arms.json and its page, arm-compatibility.md) unless --out and
--page say where."""

from __future__ import annotations

import argparse
import datetime
import json
import sys
from pathlib import Path

from tools.commands import CommandError, UsageError


def add_subparser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("arms", help="the compatibility matrix: every arm of the public model sets, imported, built "
                                    "and run (docs/arm-compatibility.md)", description=__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--sets-file", type=Path, default=None, metavar="FILE",
                   help="the list of model sets [tools/bench/model_sets.toml]")
    p.add_argument("--sets", default=None, metavar="A,B", help="only these sets (tools/bench/model_sets.toml) [all]")
    p.add_argument("--path", type=Path, default=None, metavar="DIR",
                   help="every MJCF and URDF under this folder instead of the model sets [runs/arms-NAME/ for "
                        "the results and the page]")
    p.add_argument("--match", default=None, metavar="TEXT", help="only the arms whose id contains TEXT")
    p.add_argument("--list", action="store_true", help="list the arms found, run nothing")
    p.add_argument("--missing", action="store_true",
                   help="run only the arms the results file has no row for (a run that was stopped goes on)")
    p.add_argument("--out", type=Path, default=None, help="the results file [runs/bench/arms.json]")
    p.add_argument("--page", type=Path, default=None, help="the page to render [docs/arm-compatibility.md]")
    p.set_defaults(run=run)


def run(ns: argparse.Namespace) -> int:
    from tqdm import tqdm

    from tools.bench import arms, arms_page

    if ns.path is not None and (ns.sets_file or ns.sets):
        raise UsageError("--path and --sets-file/--sets: give one (a folder, or model sets)")
    try:
        sets, left_out = ([arms.folder_set(ns.path)], []) if ns.path else arms.load_sets(ns.sets_file or arms.SETS_FILE)
    except arms.ArmsError as exc:
        raise UsageError(str(exc)) from exc
    if ns.sets:
        want = [x.strip() for x in ns.sets.split(",") if x.strip()]
        unknown = sorted(set(want) - {s.name for s in sets})
        if unknown:
            raise UsageError(f"--sets: no set {', '.join(unknown)} in {arms.SETS_FILE} "
                             f"(there: {', '.join(s.name for s in sets)})")
        sets = [s for s in sets if s.name in want]
    own = arms.REPO / "runs" / f"arms-{sets[0].name}" if ns.path else None  # a folder's matrix: its own files
    out = ns.out or (own / "arms.json" if own else arms.RESULTS)
    try:
        old = json.loads(out.read_text())
    except (OSError, ValueError):
        old = {}
    rows = {r["id"]: r for r in old.get("arms", [])}
    set_rows = {s["name"]: s for s in old.get("sets", [])}
    found = []
    for ms in sets:
        try:
            folder = arms.install(ms)
        except arms.ArmsError as exc:
            raise CommandError(str(exc)) from exc
        cands, skipped, nfiles = arms.find_arms(ms, folder)
        set_rows[ms.name] = {"name": ms.name, "requirement": ms.requirement, "licence": ms.licence,
                             "files": nfiles, "arms": len(cands), "not_arms": skipped}
        if ns.path:
            set_rows[ms.name]["path"] = str(folder)
        found += [(ms, folder, c) for c in cands if ns.match is None or ns.match in c.id]
        for rid in [r for r, row in rows.items() if row["set"] == ms.name and ns.match is None and not ns.missing]:
            del rows[rid]  # the set is run again: an arm it no longer holds goes
    if ns.list:
        for _, _, c in found:
            print(f"{c.id}  {len(c.joints)} joints" + ("  (arm file)" if c.arm_file else ""))
        return 0
    if ns.missing:
        found = [(ms, folder, c) for ms, folder, c in found if c.id not in rows]
    bound = arms.bound()
    bar = tqdm(found, desc="armctl arms", unit="arm", file=sys.stderr)
    for ms, folder, c in bar:
        bar.set_postfix_str(c.id[-40:])
        row = arms.as_dict(c) | arms.run_one(c, folder / c.model, out.parent / "arms" / c.id.replace("#", "/"), bound)
        rows[c.id] = row
        doc = {"generated_by": "tools/armctl arms", "commit": arms.commit(),
               "date": datetime.date.today().isoformat(), "machine": arms.machine(), "bound_deg": bound,
               "duration_s": arms.DURATION_S, "sets": [set_rows[k] for k in sorted(set_rows)],
               "left_out": left_out, "arms": [rows[k] for k in sorted(rows)]}
        arms.write_results(out, doc)  # after every arm: a long run keeps what it measured
        tqdm.write(f"{c.id}: {row['result']}" + (f", {row['max_error_deg']:g} deg" if row.get("max_error_deg")
                                                 is not None else "") + (f": {row['reason']}" if row.get("reason")
                                                                         else "") + f" ({row.get('first_result_s')} s)",
                   file=sys.stderr)
    page = ns.page or (own / "arm-compatibility.md" if own else arms_page.PAGE)
    if out.exists():
        if not page.exists():
            page.parent.mkdir(parents=True, exist_ok=True)
            page.write_text(arms_page.blank_page(sets[0].name))
        arms_page.render_file(out, page)
        print(f"armctl arms: {out} -> {page}")
    return 0
