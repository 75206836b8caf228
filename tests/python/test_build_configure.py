"""A build directory configures itself again when its configure failed, is junk, or was made on
another machine or with another toolchain: re-running after a fix just works (tools/build.py).
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
