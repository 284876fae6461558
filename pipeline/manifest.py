"""Stage manifests: what a finished stage was made from and what it wrote.

``manifest.json`` is written last, after every output. It records the hash of the config subtree
the stage depends on, the digests of its upstream stages' outputs, the SHA-256 of every output
file, the git revision and the timings. A stage is up to date when its manifest's config hash
and input digests equal the current ones and every listed output is present and unchanged.
"""

from __future__ import annotations

import hashlib
import json
import subprocess
from pathlib import Path
from typing import Any

from common.paths import PROJECT_ROOT

MANIFEST_NAME = "manifest.json"
MANIFEST_VERSION = 1


def file_sha256(path: Path, chunk_size: int = 1 << 20) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        while chunk := f.read(chunk_size):
            digest.update(chunk)
    return digest.hexdigest()


def hash_outputs(folder: Path) -> dict[str, dict[str, Any]]:
    """SHA-256 and size of every file below ``folder`` (relative POSIX paths), manifest excluded."""
    outputs = {}
    for path in sorted(p for p in folder.rglob("*") if p.is_file()):
        rel = path.relative_to(folder).as_posix()
        if rel == MANIFEST_NAME:
            continue
        outputs[rel] = {"sha256": file_sha256(path), "bytes": path.stat().st_size}
    return outputs


def outputs_digest(outputs: dict[str, dict[str, Any]]) -> str:
    """One hash for a stage's whole output: what its downstream stages depend on."""
    canonical = json.dumps({k: v["sha256"] for k, v in outputs.items()}, sort_keys=True)
    return hashlib.sha256(canonical.encode("utf-8")).hexdigest()


def git_revision() -> str:
    """The project's git commit, with '-dirty' when the tree has uncommitted changes."""
    try:
        rev = subprocess.run(
            ["git", "rev-parse", "HEAD"], cwd=PROJECT_ROOT, capture_output=True, text=True, timeout=10, check=True
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no"],
            cwd=PROJECT_ROOT,
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
        return rev + ("-dirty" if dirty else "")
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def read_manifest(stage_dir: Path) -> dict[str, Any] | None:
    path = stage_dir / MANIFEST_NAME
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except (FileNotFoundError, NotADirectoryError):
        return None
    except (OSError, json.JSONDecodeError):
        return None  # a damaged manifest means the stage is not known to be finished
    if not isinstance(manifest, dict) or manifest.get("version") != MANIFEST_VERSION:
        return None
    return manifest


def outputs_intact(stage_dir: Path, manifest: dict[str, Any]) -> bool:
    """Every output listed in the manifest exists with its recorded size and hash."""
    for rel, record in manifest.get("outputs", {}).items():
        path = stage_dir / rel
        try:
            if path.stat().st_size != record["bytes"]:
                return False
        except OSError:
            return False
        if file_sha256(path) != record["sha256"]:
            return False
    return True
