"""cmake/fetch_aarch64_deps.py extracts the LCM source safely on every Python 3.11: with the
tarfile "data" filter where it exists (3.11.4+), by its own checks on Debian 12's 3.11.2."""

from __future__ import annotations

import importlib.util
import io
import tarfile
from pathlib import Path

import pytest

from gen.lib.paths import REPO


def _module():
    spec = importlib.util.spec_from_file_location("fetch_aarch64_deps", REPO / "cmake" / "fetch_aarch64_deps.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)  # type: ignore[union-attr]
    return mod


def _tar(tmp: Path, members: dict[str, bytes], link: tuple[str, str] | None = None) -> Path:
    path = tmp / "src.tar"
    with tarfile.open(path, "w") as tf:
        for name, data in members.items():
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tf.addfile(info, io.BytesIO(data))
        if link:
            info = tarfile.TarInfo(link[0])
            info.type, info.linkname = tarfile.SYMTYPE, link[1]
            tf.addfile(info)
    return path


@pytest.mark.parametrize("has_filter", [True, False])
def test_extracts_a_normal_archive_and_refuses_escapes(tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                       has_filter: bool) -> None:
    mod = _module()
    if not has_filter:
        monkeypatch.delattr(tarfile, "data_filter", raising=False)
    good = _tar(tmp_path, {"lcm-1.3/lcm/lcm.c": b"int x;\n"})
    with tarfile.open(good) as tf:
        mod.safe_extract(tf, tmp_path / "out")
    assert (tmp_path / "out" / "lcm-1.3" / "lcm" / "lcm.c").read_bytes() == b"int x;\n"
    for i, (members, link) in enumerate([({"../evil.c": b"x"}, None), ({}, ("lcm/escape", "../../etc"))]):
        bad = _tar(tmp_path / f"b{i}" if (tmp_path / f"b{i}").mkdir() is None else tmp_path, members, link)
        with tarfile.open(bad) as tf, pytest.raises((SystemExit, tarfile.TarError)):
            mod.safe_extract(tf, tmp_path / f"bad{i}")
    assert not (tmp_path / "evil.c").exists()
