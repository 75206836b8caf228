"""`armctl synth --config FILE --out DIR` (also `python -m gen.synth`).

Exit codes: 0 written; 2 config error (one line naming the field); 3 design refused or
synthesis failed (nothing written).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import platform
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

REPO_ROOT = Path(__file__).resolve().parents[2]
DEFAULT_CONFIG = REPO_ROOT / "gen" / "configs" / "paper.toml"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--config",
        type=Path,
        default=DEFAULT_CONFIG,
        help=f"design config (TOML); default {DEFAULT_CONFIG.relative_to(REPO_ROOT)}",
    )
    parser.add_argument("--out", type=Path, required=True, help="output directory for the manifest and headers")
    parser.add_argument("--quiet", action="store_true", help="print nothing on success")


def synth_to_dir(config: Path, out: Path, synthesize: Callable[[Any], Any] | None = None) -> dict[str, Any]:
    """Load, design, verify, emit. Raises ConfigError / SynthesisError before writing anything.
    synthesize: gen.synth.pipeline.synthesize (the default) or a cache of it."""
    t0 = time.perf_counter()
    # Imported here, not at module level: armctl builds its parser without paying for cvxpy.
    from gen.lib.atomic_output import write_files_atomically
    from gen.synth.config import load_config
    from gen.synth.emit import design_file, fixed_header, float_header
    from gen.synth.manifest import DESIGN_FILE, FIXED_HEADER, FLOAT_HEADER, build
    from gen.synth.pipeline import synthesize as pipeline_synthesize

    cfg = load_config(config)
    design = (synthesize or pipeline_synthesize)(cfg)
    run = {
        "note": "not covered by content_hash",
        "config_file": str(config),
        "config_file_sha256": hashlib.sha256(config.read_bytes()).hexdigest(),
        "python": platform.python_version(),
        "timings_s": dict(design.timings),
    }
    manifest = build(design, run)
    files = {FLOAT_HEADER: float_header(manifest), FIXED_HEADER: fixed_header(manifest)}
    if manifest["structure"]["per_joint"]:  # the only kind a firmware runs (firmware/core/include/arm/pm.h)
        files[DESIGN_FILE] = design_file(manifest)
    manifest["run"]["timings_s"]["total_in_process_s"] = time.perf_counter() - t0
    files["manifest.json"] = json.dumps(manifest, indent=1, allow_nan=False) + "\n"
    write_files_atomically(out, files)
    return manifest


def _summary(m: dict[str, Any], out: Path) -> str:
    e, c = m["estimator"], m["controller"]
    cl = m["verification"]["combined_loop"]
    lines = [
        f"synth: {m['structure']['mode']} design, {m['structure']['n_joints']} joints, {m['loop_rate_hz']} Hz -> {out}",
        f"  estimator  (H-inf):  gamma_opt {e['gamma_opt']:.6f}  gamma_design {e['gamma_design']:.6f}  "
        f"verified {m['verification']['estimator_loop']['hinf_norm']:.6f}",
        f"  controller (gen-H2): gamma_opt {c['gamma_opt']:.3g}  gamma_design {c['gamma_design']:.6g}  "
        f"verified {m['verification']['controller_loop']['gh2_norm']:.6g}" + ("  [degenerate: static zeroing gain]" if c["degenerate"] else ""),
        "  sampled loop spectral radius (nominal / delayed): "
        + ", ".join(f"{s} {cl[s]['sampled_spectral_radius']:.7f} / {cl[s]['sampled_spectral_radius_delayed']:.7f}" for s in cl),
        f"  hash {m['content_hash'][:16]}  ({m['run']['timings_s']['total_in_process_s']:.2f} s)",
    ]
    return "\n".join(lines)


CACHE_FILES = ("manifest.json", "pm_design_float.h", "pm_design_fixed.h", "pm_design.txt")


def _cache_dir(config: Path) -> Path | None:
    """Where the design of this very config text is kept (build/synth-cache/<digest>), by the config's
    bytes and the synthesis code's: a design is solved once, whichever arm or build folder asks for
    it again (an arm's first build pays for cvxpy only when its design is new)."""
    from gen.lib.paths import BUILD

    try:
        h = hashlib.sha256(config.read_bytes())
    except OSError:
        return None
    for src in sorted((REPO_ROOT / "gen" / "synth").glob("*.py")):
        h.update(src.read_bytes())
    return BUILD / "synth-cache" / h.hexdigest()[:32]


def _from_cache(config: Path, out: Path) -> dict[str, Any] | None:
    """The kept design written to out (its manifest naming this config file), or None."""
    from gen.lib.atomic_output import write_files_atomically

    cache = _cache_dir(config)
    if cache is None or not all((cache / f).is_file() for f in CACHE_FILES[:3]):
        return None
    files = {f: (cache / f).read_text() for f in CACHE_FILES if (cache / f).is_file()}
    manifest = json.loads(files["manifest.json"])
    manifest["run"]["config_file"] = str(config)
    manifest["run"]["from_cache"] = str(cache)
    files["manifest.json"] = json.dumps(manifest, indent=1, allow_nan=False) + "\n"
    write_files_atomically(out, files)
    return manifest


def _keep(config: Path, out: Path) -> None:
    from gen.lib.atomic_output import write_files_atomically

    cache = _cache_dir(config)
    if cache is not None:
        try:
            write_files_atomically(cache, {f: (out / f).read_text() for f in CACHE_FILES if (out / f).is_file()})
        except OSError:
            pass  # a cache that cannot be written is only a slower next build


def run(ns: argparse.Namespace) -> int:
    from gen.lib.outdir import OutDirError, check_out_dir

    try:
        check_out_dir(ns.out)
        kept = _from_cache(ns.config, ns.out)
    except (OutDirError, OSError, ValueError, KeyError):
        kept = None
    if kept is not None:
        if not getattr(ns, "quiet", False):
            print(_summary(kept, ns.out))
        return 0
    from gen.lib.atomic_output import OutputError
    from gen.synth.config import ConfigError
    from gen.synth.lmi import SynthesisError

    from gen.lib.outdir import OutDirError, check_out_dir

    try:
        check_out_dir(ns.out)  # before the solve, not after it
        manifest = synth_to_dir(ns.config, ns.out)
    except (ConfigError, OutDirError) as exc:
        print(f"config error: {exc}", file=sys.stderr)
        return 2
    except SynthesisError as exc:
        print(f"synth refused: {exc}", file=sys.stderr)
        return 3
    except OutputError as exc:
        print(f"synth: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:
        print(f"synth: cannot write {ns.out}: {exc}", file=sys.stderr)
        return 1
    _keep(ns.config, ns.out)
    if not getattr(ns, "quiet", False):
        print(_summary(manifest, ns.out))
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m gen.synth", description=__doc__.splitlines()[0] if __doc__ else None)
    add_arguments(parser)
    return run(parser.parse_args(argv))
