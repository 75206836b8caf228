"""armctl render: a run's arm as the simulator moved it, beside its commanded reference (a
translucent ghost): a short video and a frame strip (tools/run/render.py), rendered on the CPU."""

from __future__ import annotations

import argparse
from pathlib import Path

from tools.commands import CommandError


def add_subparser(sub: argparse._SubParsersAction) -> None:
    r = sub.add_parser("render", help="a run's arm beside its reference: a video and a frame strip (start, middle, "
                                      "worst tracking, end)")
    r.add_argument("run_dir", type=Path, metavar="RUN_DIR", help="a run's folder (armctl hil --out, or a study's "
                                                                 "SCENARIO/METHOD/seed-N)")
    r.add_argument("--out", type=Path, default=None, metavar="DIR", help="where to write them [RUN_DIR]")
    r.add_argument("--no-video", dest="video", action="store_false", help="the frame strip alone")
    r.set_defaults(run=run)


def run(ns: argparse.Namespace) -> int:
    from tqdm import tqdm

    from tools.run.render import STRIP_FILE, RenderError, write_strip, write_video

    out = ns.out or ns.run_dir
    if ns.out is not None and not ns.out.is_dir():
        raise CommandError(f"--out {ns.out}: no such folder", 2)
    try:
        rec = write_strip(ns.run_dir, out)
        print(f"strip: {out / STRIP_FILE} ("
              + ", ".join(f"{p['moment']} at {p['t_s']:.3f} s, largest |e| {p['max_abs_e_deg']:.3g} deg"
                          for p in rec["panels"]) + ")")
        if ns.video:
            bar = tqdm(desc="render", unit="frame")

            def progress(done: int, total: int) -> None:
                bar.total = total
                bar.update(done - bar.n)

            video = write_video(ns.run_dir, out, progress)
            bar.close()
            print(f"video: {video}")
    except RenderError as exc:
        raise CommandError(str(exc), exc.code) from None
    if rec.get("log_damage"):  # drawn from what could be read: said, and not a success
        raise CommandError(f"the run's telemetry log is damaged: {rec['log_damage']}; the strip"
                           + (" and the video show" if ns.video else " shows") + " the periods read", 1)
    return 0
