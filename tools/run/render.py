"""A run's arm, seen: MuJoCo's offscreen renderer on the CPU (EGL on Mesa's software device, no
display and no GPU), the arm as the simulator moved it beside its commanded reference, a
translucent ghost. `armctl render RUN_DIR` writes a short video and a frame strip (the start, the
middle, the run's worst-tracking moment and the end); a study report shows the strip of each
scenario's worst run; an imported arm's first `armctl hil` run writes it.

The run's arm is its prepared model (the build folder run.json names: generated/arm/arm.xml),
which keeps the chain's dynamics and none of its geometry, so the arm is drawn from its kinematics:
a capsule from each body's origin to its child's (and to its sites, the flange), a short cylinder
along each joint's axis at its anchor. A flipped axis, a wrong frame or a joint that should not
move shows as it is. The arm is where the simulator had it (ARM_SIM's q, the links' side of a
flexible joint); the reference is the controller's q_d of the same period (ARM_CTL).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

from gen.lib.atomic_output import write_bytes_atomic, write_json_atomic
from gen.lib.one_line import one_line
from tools.build.arm import prepared_model
from tools.run.run_files import RUN_RECORD, TELEMETRY_LOG
from tools.run.telemetry_log import LogDamage, read_log, truth_rows

STRIP_FILE = "arm-strip.png"
VIDEO_FILE = "arm.mp4"
PANEL = (400, 300)                    # one moment of the strip, width x height (pixels)
VIDEO_SIZE = (480, 320)               # multiples of 16, as H.264 wants them
CAPTION_H = 44                        # the text above each panel of the strip
VIDEO_FPS = 20
VIDEO_MAX_S = 12.0                    # a longer run is shown faster: the video stays short
ARM_RGBA = (0.22, 0.42, 0.78, 1.0)    # the simulated arm: opaque
JOINT_RGBA = (0.93, 0.55, 0.12, 1.0)  # its joints' axes
GHOST_RGBA = (0.15, 0.75, 0.30, 0.35)  # the reference: translucent
FLOOR_RGBA = (0.86, 0.86, 0.84, 1.0)
BACKGROUND = (255, 255, 255)          # where nothing was drawn (depth at the far plane)
AZIMUTH, ELEVATION, FOVY = 135.0, -25.0, 45.0


class RenderError(Exception):
    """A run that cannot be rendered: a one-line reason naming the file or what is missing; exit
    `code` (2: the input, 1: this machine)."""

    def __init__(self, message: str, code: int = 2) -> None:
        super().__init__(message)
        self.code = code

    def __reduce__(self) -> tuple[type, tuple[str, int]]:  # its code kept across processes (write_strip_apart)
        return RenderError, (str(self), self.code)


@dataclass
class Motion:
    """A run's arm over time: the simulator's q and the controller's q_d, per controller period."""
    t: np.ndarray          # s, the controller's time
    q: np.ndarray          # (k, n) rad, the arm
    q_d: np.ndarray        # (k, n) rad, the reference
    e: np.ndarray          # (k, n) rad, the controller's tracking error
    joint_names: list[str]
    result: str
    method: str
    hold_s: float          # the reference holds its start this long before the trajectory begins
    stopped: bool          # the run ended before its trajectory did (the safety layer stopped it)
    damage: str | None = None  # where its telemetry log breaks and what was left unread (None: whole)


def load_run(run_dir: Path) -> tuple[dict[str, Any], Path]:
    """run.json and the prepared model of the build it names (checked to be the model that ran)."""
    path = run_dir / RUN_RECORD
    try:
        run = json.loads(path.read_text())
        build = Path(run["environment"]["build"])
        ran_hash = run["results"]["arm"]["model_hash"]
    except FileNotFoundError:
        raise RenderError(f"{path}: no such file: not a run folder (armctl hil --out writes one)") from None
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise RenderError(f"{path}: not a run's results ({type(exc).__name__}: {exc})") from None
    model = prepared_model(build)
    info_path = model.with_name("arm.json")
    try:
        built_hash = json.loads(info_path.read_text())["model_hash"]
    except (OSError, ValueError, KeyError) as exc:
        raise RenderError(f"{info_path}: the run's build (run.json environment.build) has no prepared arm ({exc}): "
                          "build that arm again with tools/armctl build --model/--arm") from None
    if built_hash != ran_hash:
        raise RenderError(f"{info_path}: the build now holds model {built_hash}, the run ran {ran_hash}: build the "
                          "run's arm again (tools/armctl build --model/--arm) to render it")
    return run, model


def load_motion(run_dir: Path, run: dict[str, Any]) -> Motion:
    """The periods the controller ran (state running) with the simulator's q of each."""
    log_path = run_dir / TELEMETRY_LOG
    if not log_path.exists():
        raise RenderError(f"{log_path}: no such file: the run kept no telemetry")
    damage = LogDamage()
    log = read_log(log_path, channels=("ARM_CTL", "ARM_SIM"), damage=damage)
    ctl, sim = log["ARM_CTL"].messages, log["ARM_SIM"].messages
    res = run["results"]
    ctl = ctl[ctl.state == 1]
    if len(ctl) == 0:
        raise RenderError(f"{log_path}: the controller never ran (result {res.get('result')}): no motion to render")
    at = truth_rows(ctl, sim)
    q = np.where((at >= 0)[:, None], sim.q[np.maximum(at, 0)], ctl.q.astype(float)) if len(sim) else ctl.q.astype(float)
    hold, rate = float(res.get("ref_hold_s") or 0.0), float(res.get("rate_hz") or 1000.0)
    end = hold + float(res.get("duration_s") or 0.0)
    return Motion(t=ctl.t.astype(float), q=q.astype(float), q_d=ctl.q_d.astype(float), e=ctl.e.astype(float),
                  joint_names=list(res.get("joint_names") or []), result=str(res.get("result")),
                  method=str(res.get("method")), hold_s=hold, stopped=float(ctl.t[-1]) < end - 2.0 / rate,
                  damage=f"{log_path}: {damage.describe()}" if damage.damaged else None)


def moments(mo: Motion) -> list[tuple[str, int]]:
    """The strip's moments, in time order: start, middle, the worst tracking (the largest |e| of
    any joint) and the end (where a run that stopped early stopped); moments that fall on one
    period are one panel, named by both ("worst, stopped")."""
    k = len(mo.t)
    worst = int(np.argmax(np.abs(mo.e).max(axis=1)))
    picks = [("start", 0), ("middle", k // 2), ("worst", worst), ("stopped" if mo.stopped else "end", k - 1)]
    names: dict[int, list[str]] = {}
    for label, i in sorted(picks, key=lambda p: (p[1], p[0] != "worst")):
        names.setdefault(i, []).append(label)
    return [(", ".join(labels), i) for i, labels in names.items()]


class ArmView:
    """An offscreen renderer of one prepared model: the arm at q, its reference ghost at q_d beside it."""

    def __init__(self, model_path: Path, size: tuple[int, int], poses: np.ndarray) -> None:
        import mujoco
        from mujoco.egl import GLContext  # EGL whatever MUJOCO_GL said when mujoco was imported

        self.mj = mujoco
        try:
            self.m = mujoco.MjModel.from_xml_path(str(model_path))
        except Exception as exc:  # noqa: BLE001 - MuJoCo's ValueError names the element
            raise RenderError(f"{model_path}: the prepared model does not load: {exc}") from None
        self.w, self.h = size
        self.m.vis.global_.offwidth = max(self.w, int(self.m.vis.global_.offwidth))
        self.m.vis.global_.offheight = max(self.h, int(self.m.vis.global_.offheight))
        self.m.vis.global_.fovy = FOVY
        self.m.vis.headlight.ambient[:] = 0.45  # the floor lit from the camera's side, the links still shaded
        self.m.vis.headlight.diffuse[:] = 0.6
        try:
            self.gl = GLContext(self.w, self.h)
            self.gl.make_current()
        except Exception as exc:  # noqa: BLE001 - PyOpenGL and EGL raise their own
            raise RenderError(f"no EGL device to render with ({type(exc).__name__}: {exc}); MuJoCo renders on the "
                              "CPU through Mesa: install libegl1, libegl-mesa0 and libgl1-mesa-dri", 1) from None
        self.d = mujoco.MjData(self.m)
        self.ghost = mujoco.MjData(self.m)
        self.con = mujoco.MjrContext(self.m, mujoco.mjtFontScale.mjFONTSCALE_100)
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN, self.con)
        self.scene = mujoco.MjvScene(self.m, maxgeom=10 * (self.m.nbody + self.m.njnt + self.m.nsite) + 100)
        self.opt = mujoco.MjvOption()
        self.cam = mujoco.MjvCamera()
        self.viewport = mujoco.MjrRect(0, 0, self.w, self.h)
        self.radius = 0.03 * max(float(self.m.stat.extent), 0.1)
        self._frame(poses)

    def _points(self, d: Any) -> np.ndarray:
        return np.concatenate([d.xpos[1:], d.site_xpos]) if self.m.nsite else d.xpos[1:].copy()

    def _frame(self, poses: np.ndarray) -> None:
        """One camera for every frame: it sees the arm and the ghost in every pose of the run."""
        pts = []
        for q in poses:
            self.d.qpos[:] = q
            self.mj.mj_kinematics(self.m, self.d)
            pts.append(self._points(self.d))
        p = np.concatenate(pts)
        self.base = p[0].copy()  # the first body's origin, where a label names the arm
        az, el = math.radians(AZIMUTH), math.radians(ELEVATION)
        self.forward = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
        self.right = np.array([math.sin(az), -math.cos(az), 0.0])
        self.up = np.cross(self.right, self.forward)
        reach = float(np.ptp(p @ self.right)) + 2 * self.radius
        self.offset = self.right * (1.35 * reach)  # the ghost stands beside the arm, to its right, never through it
        both = np.concatenate([p, p + self.offset])
        lo, hi = both.min(axis=0) - self.radius, both.max(axis=0) + self.radius
        self.floor_z = float(lo[2])
        self.cam.type = self.mj.mjtCamera.mjCAMERA_FREE
        self.cam.lookat[:] = (lo + hi) / 2
        self.cam.azimuth, self.cam.elevation = AZIMUTH, ELEVATION
        # the nearest camera on this line of sight that has every point inside its field of view,
        # then the line of sight moved to the middle of what it sees (the points' depths differ)
        ty = math.tan(math.radians(FOVY) / 2)
        tx = ty * self.w / self.h
        margin = 4 * self.radius
        for _ in range(4):
            rel = both - self.cam.lookat
            need = np.maximum((np.abs(rel @ self.right) + margin) / tx, (np.abs(rel @ self.up) + margin) / ty)
            self.cam.distance = float((need - rel @ self.forward).max())
            depth = self.cam.distance + rel @ self.forward
            x, y = (rel @ self.right) / (depth * tx), (rel @ self.up) / (depth * ty)
            shift = ((x.max() + x.min()) / 2 * tx * self.right + (y.max() + y.min()) / 2 * ty * self.up)
            self.cam.lookat[:] = self.cam.lookat + shift * self.cam.distance

    def pixel(self, point: np.ndarray) -> tuple[float, float]:
        """Where a point of the world is in the image (x right, y down, pixels)."""
        rel = point - (self.cam.lookat - self.cam.distance * self.forward)
        depth = float(rel @ self.forward)
        ty = math.tan(math.radians(FOVY) / 2)
        return (self.w / 2 * (1 + float(rel @ self.right) / (depth * ty * self.w / self.h)),
                self.h / 2 * (1 - float(rel @ self.up) / (depth * ty)))

    def _add(self, kind: int, rgba: tuple[float, ...], size: Any = (0, 0, 0), pos: Any = (0, 0, 0),
             a: np.ndarray | None = None, b: np.ndarray | None = None, width: float = 0.0) -> None:
        if self.scene.ngeom >= self.scene.maxgeom:
            return
        g = self.scene.geoms[self.scene.ngeom]
        self.mj.mjv_initGeom(g, kind, np.asarray(size, float), np.asarray(pos, float), np.eye(3).ravel(),
                             np.asarray(rgba, np.float32))
        if a is not None and b is not None:
            self.mj.mjv_connector(g, kind, width, a, b)
        self.scene.ngeom += 1

    def _arm(self, d: Any, q: np.ndarray, offset: np.ndarray, rgba: tuple[float, ...], joints: tuple[float, ...]) -> None:
        G = self.mj.mjtGeom
        d.qpos[:] = q
        self.mj.mj_kinematics(self.m, d)
        r = self.radius
        for b in range(1, self.m.nbody):
            a, c = d.xpos[self.m.body_parentid[b]] + offset, d.xpos[b] + offset
            if np.linalg.norm(c - a) > 1e-6:
                self._add(G.mjGEOM_CAPSULE, rgba, a=a, b=c, width=r)
            else:
                self._add(G.mjGEOM_SPHERE, rgba, size=(r, r, r), pos=c)
        for s in range(self.m.nsite):
            a, c = d.xpos[self.m.site_bodyid[s]] + offset, d.site_xpos[s] + offset
            if np.linalg.norm(c - a) > 1e-6:
                self._add(G.mjGEOM_CAPSULE, rgba, a=a, b=c, width=0.7 * r)
        for j in range(self.m.njnt):
            at, axis = d.xanchor[j] + offset, d.xaxis[j]
            self._add(G.mjGEOM_CYLINDER, joints, a=at - 1.6 * r * axis, b=at + 1.6 * r * axis, width=1.5 * r)

    def render(self, q: np.ndarray | None, q_d: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """RGB (h, w, 3) uint8 and whether each pixel shows something (h, w) bool: the arm at q
        (None: not drawn) and the ghost at q_d beside it (None: not drawn), on a floor."""
        mj = self.mj
        self.d.qpos[:] = q if q is not None else self.m.qpos0
        mj.mj_forward(self.m, self.d)
        mj.mjv_updateScene(self.m, self.d, self.opt, None, self.cam, mj.mjtCatBit.mjCAT_ALL, self.scene)
        self.scene.ngeom = 0  # the prepared model's own geometry, if any, is not the arm we draw
        span = 3 * float(self.m.stat.extent) + np.linalg.norm(self.offset)
        self._add(mj.mjtGeom.mjGEOM_PLANE, FLOOR_RGBA, size=(span, span, 0.05),
                  pos=(*(self.cam.lookat[:2]), self.floor_z))
        if q is not None:
            self._arm(self.d, q, np.zeros(3), ARM_RGBA, JOINT_RGBA)
        if q_d is not None:
            self._arm(self.ghost, q_d, self.offset, GHOST_RGBA, GHOST_RGBA)
        mj.mjr_render(self.viewport, self.scene, self.con)
        rgb = np.empty((self.h, self.w, 3), np.uint8)
        depth = np.empty((self.h, self.w), np.float32)
        mj.mjr_readPixels(rgb, depth, self.viewport, self.con)
        drawn = depth < 1.0
        rgb[~drawn] = BACKGROUND
        return np.flipud(rgb).copy(), np.flipud(drawn).copy()

    def close(self) -> None:
        self.con.free()
        self.gl.free()


def _font(size: int) -> Any:
    from PIL import ImageFont

    return ImageFont.load_default(size=size)


def _caption(mo: Motion, label: str, i: int) -> str:
    worst = int(np.argmax(np.abs(mo.e[i])))
    name = mo.joint_names[worst] if worst < len(mo.joint_names) else f"joint {worst + 1}"
    return f"{label}: t {mo.t[i]:.3f} s, largest |e| {np.degrees(abs(mo.e[i, worst])):.3g} deg ({one_line(name)})"


def write_strip(run_dir: Path, out: Path | None = None, name: str = STRIP_FILE) -> dict[str, Any]:
    """The frame strip of a run (OUT/NAME, default RUN_DIR/STRIP_FILE) and its record (the same
    name, .json: the moments, each panel's box in the PNG, the ghost's offset): the record."""
    from PIL import Image, ImageDraw

    out = out or run_dir
    run, model = load_run(run_dir)
    mo = load_motion(run_dir, run)
    picks = moments(mo)
    w, h = PANEL
    view = ArmView(model, PANEL, np.concatenate([mo.q, mo.q_d]))
    try:
        panels = [(label, i, view.render(mo.q[i], mo.q_d[i])[0]) for label, i in picks]
    finally:
        view.close()
    title_h = 26
    img = Image.new("RGB", (w * len(panels), title_h + CAPTION_H + h), BACKGROUND)
    draw = ImageDraw.Draw(img)
    parts = run_dir.resolve().parts
    where = str(run_dir.resolve()) if len(parts) <= 4 else "/".join(parts[-3:])  # a study's SCENARIO/METHOD/seed-N
    draw.text((6, 4), f"{one_line(where)}: {mo.method}, {mo.result}. Solid blue: the arm as simulated (orange: its joint axes); "
                      "translucent green, beside it: the commanded reference. t from the run's start (the "
                      f"trajectory begins after a {mo.hold_s:g} s hold)"
                      + ("; ITS TELEMETRY LOG IS DAMAGED: the periods read (the .json says where it breaks)"
                         if mo.damage else ""), fill=(0, 0, 0), font=_font(13))
    boxes = []
    names = [(view.pixel(view.base), "arm"), (view.pixel(view.base + view.offset), "reference")]
    for k, (label, i, rgb) in enumerate(panels):
        x = k * w
        img.paste(Image.fromarray(rgb), (x, title_h + CAPTION_H))
        for (px, py), who in names:
            draw.text((x + px, title_h + CAPTION_H + min(py + 14, h - 10)), who, fill=(60, 60, 60), font=_font(12),
                      anchor="mm")
        words = _caption(mo, label, i).split(", largest")
        draw.text((x + 6, title_h + 2), words[0], fill=(0, 0, 0), font=_font(14))
        draw.text((x + 6, title_h + 22), "largest" + words[1], fill=(0, 0, 0), font=_font(12))
        if k:
            draw.line([(x, title_h), (x, title_h + CAPTION_H + h)], fill=(160, 160, 160))
        boxes.append({"moment": label, "t_s": float(mo.t[i]), "index": i, "box": [x, title_h + CAPTION_H, w, h],
                      "max_abs_e_deg": float(np.degrees(np.abs(mo.e[i]).max()))})
    import io

    buf = io.BytesIO()
    img.save(buf, format="PNG")
    write_bytes_atomic(out / name, buf.getvalue())
    record = {"run": str(run_dir), "model": str(model), "method": mo.method, "result": mo.result,
              "panels": boxes, "arm_rgba": ARM_RGBA, "ghost_rgba": GHOST_RGBA, "ghost_offset_m": view.offset.tolist(),
              "log_damage": mo.damage}
    write_json_atomic((out / name).with_suffix(".json"), record)
    return record


def write_strip_apart(run_dir: Path, out: Path | None = None, name: str = STRIP_FILE) -> dict[str, Any]:
    """write_strip in a fresh interpreter of its own. For a caller that may be a fork: once a
    process has rendered, Mesa's llvmpipe keeps worker threads, and a fork of that process waits
    for them forever in its first render (a study drawn after a render in the same process)."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(max_workers=1, mp_context=multiprocessing.get_context("spawn")) as pool:
        return pool.submit(write_strip, run_dir, out, name).result()


def write_video(run_dir: Path, out: Path | None = None, progress: Callable[[int, int], None] | None = None) -> Path:
    """The run as a video (VIDEO_FILE, H.264 through imageio-ffmpeg's ffmpeg): at most VIDEO_MAX_S
    long at VIDEO_FPS, the time and the largest |e| written on each frame."""
    import imageio_ffmpeg
    from PIL import Image, ImageDraw

    out = out or run_dir
    run, model = load_run(run_dir)
    mo = load_motion(run_dir, run)
    span = float(mo.t[-1] - mo.t[0])
    speed = max(1.0, span / VIDEO_MAX_S)
    times = mo.t[0] + np.arange(0.0, span + 1e-9, speed / VIDEO_FPS)
    idx = np.minimum(np.searchsorted(mo.t, times), len(mo.t) - 1)
    view = ArmView(model, VIDEO_SIZE, np.concatenate([mo.q, mo.q_d]))
    target = out / VIDEO_FILE
    tmp = target.with_name(f".{target.name}.tmp.mp4")
    font = _font(13)
    try:
        writer = imageio_ffmpeg.write_frames(str(tmp), VIDEO_SIZE, fps=VIDEO_FPS, codec="libx264",
                                             pix_fmt_out="yuv420p", macro_block_size=16, quality=7,
                                             output_params=["-movflags", "+faststart"])
        writer.send(None)
        for k, i in enumerate(idx):
            img = Image.fromarray(view.render(mo.q[i], mo.q_d[i])[0])
            ImageDraw.Draw(img).text((6, 4), _caption(mo, "", int(i))[2:] + (f"  ({speed:.2g}x)" if speed > 1 else ""),
                                     fill=(0, 0, 0), font=font)
            writer.send(np.asarray(img))
            if progress:
                progress(k + 1, len(idx))
        writer.close()
        tmp.replace(target)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    finally:
        view.close()
    return target
