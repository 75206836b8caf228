"""A build directory configures itself again when its configure failed, is junk, or was made on
another machine or with another toolchain: re-running after a fix just works (tools/build/__init__.py).
Uses the Cortex-M3 image (the cheapest full configure + build) in a directory of its own."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from tools.build import STAMP, ConfigureFailed, build

pytestmark = pytest.mark.skipif(shutil.which("arm-none-eabi-gcc") is None,
                                reason="arm-none-eabi-gcc not found (tools/armctl installs it as root)")


def test_junk_failed_and_foreign_configures_are_redone(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bdir = tmp_path / "cortex-m3"
    bdir.mkdir()
    (bdir / "CMakeCache.txt").write_text("junk\n")
    build("cortex-m3", bdir=bdir)
    assert (bdir / "build.ninja").exists() and (bdir / STAMP).exists()
    assert "no record of a successful configure" in capsys.readouterr().err

    # a configure that fails: CMake's own message is shown, and no record of success is left
    with pytest.raises(ConfigureFailed, match="configure failed"):
        build("cortex-m3", bdir=bdir, cache={"ARM_MODEL": str(tmp_path / "no-such-arm.xml")})
    assert "ARM_MODEL" in capsys.readouterr().err and not (bdir / STAMP).exists()
    build("cortex-m3", bdir=bdir)  # the fix: just run again
    assert (bdir / STAMP).exists()
    capsys.readouterr()

    build("cortex-m3", bdir=bdir)  # nothing changed: not configured again
    assert "configuring" not in capsys.readouterr().err

    for field, value in (("machine", "another-machine"), ("compiler:arm-none-eabi-gcc", "/opt/other/gcc 9.0")):
        stamp = json.loads((bdir / STAMP).read_text())
        stamp[field] = value
        (bdir / STAMP).write_text(json.dumps(stamp))
        build("cortex-m3", bdir=bdir)
        assert f"configured with a different {field}" in capsys.readouterr().err
        assert json.loads((bdir / STAMP).read_text())[field] != value


def test_a_second_build_of_the_same_folder_waits_for_the_first() -> None:
    """Two builders in one build folder corrupt it (two `armctl build --model X` at once: "file
    truncated" at the link). This process holds the folder's build lock as a first build would;
    `armctl build` in another process waits, saying so, and builds once it is released."""
    import subprocess
    import time

    from tools.build import build_lock
    from gen.lib.paths import REPO, build_dir

    with build_lock(build_dir("release")):
        p = subprocess.Popen([str(REPO / "tools" / "armctl"), "build", "--preset", "release"], cwd=REPO,
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        time.sleep(4.0)  # a no-op build takes about 1 s
        assert p.poll() is None, p.communicate()
    out, err = p.communicate(timeout=300)
    assert p.returncode == 0, err
    assert f"waiting for another build in {build_dir('release')}" in err


def test_a_prebuilt_folder_is_not_checked_again_but_must_be_built(tmp_path: Path,
                                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    """ARMCTL_PREBUILT (what the qemu VM's commands get: the host built the tree they share): a
    listed folder is not configured or built again, yet one with no configure record or no
    controller is refused in one line, never run as it is."""
    from tools.build import PREBUILT_ENV, BuildError, prebuilt
    from gen.lib.paths import controller_binary

    bdir = tmp_path / "release"
    bdir.mkdir()
    assert not prebuilt(bdir)  # not listed: the usual check
    monkeypatch.setenv(PREBUILT_ENV, f"{tmp_path / 'other'}:{bdir}")
    with pytest.raises(BuildError, match=f"{bdir} is in {PREBUILT_ENV} but not built"):
        prebuilt(bdir)
    (bdir / STAMP).write_text("{}")
    controller_binary(bdir).parent.mkdir(parents=True)
    controller_binary(bdir).write_text("")
    assert prebuilt(bdir)
    build("release", bdir=bdir)  # returns at once: no CMake, no ninja in an empty folder
    assert not (bdir / "build.ninja").exists()
