"""A newcomer's tasks, one page each (docs/index.md "Your tasks"): each page holds the task's whole
command sequence in one block marked `<!-- task:NAME -->`, and each sequence runs, command after
command, through tools/armctl as a user types it. The runs are the short form of each command
(SHORT: a shorter trajectory, one scenario, two trials), with the page's placeholders (`my_arm.toml`,
`my_drive.eds`, `PICK`) standing for files of the repository, and `runs/` for a temporary folder.
`tools/armctl test` (the whole suite) is run by CI, as test_documented_commands.py says."""

from __future__ import annotations

import json
import re
import shlex
import subprocess
from pathlib import Path

import pytest

from gen.lib.paths import DOCS, REPO
from study_configs import with_tuning

# task -> its page. Running the controller on a real arm is a task of its own page too, which
# comes with `tools/armctl run` (not here yet: no task marker to hold).
TASKS = {"demo": "quickstart.md", "own-arm": "arm.md", "own-drives": "drives-bring-up.md", "pil": "pil.md",
         "pick-a-method": "study.md"}
MARKER = re.compile(r"^<!-- task:(?P<name>[a-z-]+) -->\n```sh\n(?P<block>.*?)^```", re.S | re.M)
BY_CI = {"tools/armctl test"}  # the whole suite: CI runs it (test_documented_commands.py EXERCISED)

ARM = str(REPO / "tests" / "arms" / "panda.toml")
MODEL = str(REPO / "tests" / "arms" / "robosuite" / "iiwa.xml")
DRIVE = str(REPO / "tests" / "drives" / "maxon_epos4_50_15.dcf")


def drive_table(tmp: Path) -> Path:
    """A user's table for six maxon EPOS4 on the bundled arm: the vendor's drive table
    (tests/drives/), with TPDO2 every 2nd SYNC, as the bundled table has it, so that six drives fit
    classic 1 Mbit/s buses at 1 kHz (every SYNC they do not: `busload` says so and exits 2)."""
    table = tmp / "my_drives.toml"
    text = (REPO / "tests" / "drives" / "maxon_epos4_50_15.toml").read_text().replace(
        'eds = "maxon_epos4_50_15.dcf"', f'eds = "{DRIVE}"')
    pdo = (REPO / "firmware" / "protocol" / "drives.toml").read_text().split("\n[pdo]\n")[1]
    table.write_text(text + "\n[pdo]\n" + pdo)
    return table


def sequences() -> dict[str, tuple[str, list[str]]]:
    """task -> (the page that holds its block, the block's commands, comments dropped)."""
    out: dict[str, tuple[str, list[str]]] = {}
    for page in sorted(DOCS.rglob("*.md")):
        for m in MARKER.finditer(page.read_text()):
            assert m.group("name") not in out, f"task {m.group('name')}: on {out.get(m.group('name'), ('',))[0]} and {page}"
            cmds = [line.split("  #")[0].strip() for line in m.group("block").splitlines()]
            out[m.group("name")] = (str(page.relative_to(DOCS)), [c for c in cmds if c])
    return out


def test_every_task_has_one_page_with_its_whole_sequence() -> None:
    """Each task's block is on its page, and every command in it is a documented command of
    tools/armctl (docs/reference/commands.md), so the command table's tests cover its options too."""
    from test_documented_commands import documented_commands

    found = sequences()
    assert {t: p for t, (p, _) in found.items()} == TASKS
    documented = {c.split()[0] for c in documented_commands()}
    for task, (_, cmds) in found.items():
        assert cmds, task
        for c in cmds:
            words = shlex.split(c)
            assert words[0] == "tools/armctl" and words[1] in documented, (task, c)
    index = (DOCS / "index.md").read_text()
    assert all(f"]({page})" in index for page in TASKS.values()), "docs/index.md lists every task's page"


def short_form(task: str, cmd: str, tmp: Path) -> str:
    """The command as the test runs it: placeholders filled, outputs in tmp, the short form."""
    cfg = tmp / "small.toml"
    if not cfg.exists():
        cfg.write_text(with_tuning((REPO / "tools" / "studies" / "paper.toml").read_text(), duration_s=0.2, batch=2))
    cmd = (cmd.replace("my_arm.xml", MODEL).replace("my_arm.toml", ARM).replace("my_drive.eds", DRIVE)
           .replace("my_drives.toml", str(drive_table(tmp))).replace(" runs/", f" {tmp}/runs/"))
    cmd = re.sub(r"--duration \d+(\.\d+)?", "--duration 0.5", cmd)
    sub = shlex.split(cmd)[1]
    if sub == "demo":
        cmd += f" --duration 0.2 --scenarios realistic --no-figures --out {tmp}/runs/demo"
    elif sub in ("tune", "study"):
        cmd += f" --config {cfg} --scenarios realistic --methods pd,tde --trials 2"
        cmd += f" --out {tmp}/runs/tune" if sub == "tune" else " --seeds 1 --duration 0.5 --no-figures"
    elif sub == "hil" and "--tuned" in cmd:
        cmd += f" --config {cfg}"
    elif sub == "bench":
        cmd += f" --quick --out {tmp}/runs/bench-pil.json"
    return cmd


def _pick(tmp: Path) -> str:
    from tools.study.answer import ranking

    study = json.loads((tmp / "runs" / "my-study" / "study.json").read_text())
    return ranking(study, "realistic")[0][0]


@pytest.mark.long
@pytest.mark.parametrize("task", sorted(TASKS))
def test_the_tasks_sequence_runs(task: str, tmp_path: Path) -> None:
    _, cmds = sequences()[task]
    for cmd in cmds:
        if cmd in BY_CI:
            continue
        if "PICK" in cmd:
            cmd = cmd.replace("PICK", _pick(tmp_path))
        line = short_form(task, cmd, tmp_path)
        r = subprocess.run(["bash", "-c", line], cwd=REPO, capture_output=True, text=True, timeout=3600)
        assert r.returncode == 0, f"{task}: {line}\n{r.stdout[-3000:]}{r.stderr[-3000:]}"
