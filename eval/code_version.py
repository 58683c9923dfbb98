"""Which version of the project's code a run ran: one version per sweep, named in every record.

A sweep runs for hours; its processes import modules as they need them (a pool worker is spawned fresh, gymnasium
imports an env's module at ``gym.make``, a figure's module at its start), so a library change made while it runs would
make some of its runs with the old code and some with the new. Here:

- :func:`code_version` is the code this process runs: the git commit, whether the project's source differs from it
  (dirty), and a digest of the source files themselves (``SOURCE_PACKAGES``; what git cannot see, e.g. an installed
  copy, is still told apart). It is read the first time it is asked, which a sweep does at its start
  (``LocalExecutor.map``), and handed to the sweep's worker processes (:func:`pin_code_version`).
- :func:`check_code_unchanged` compares the source on disk with it: ``eval.run.run_job`` checks before a run
  starts and again before it writes its record, and refuses a run whose code changed since the sweep started.
- Each run's ``metrics.json`` and ``config.yaml`` carry the version (key ``code``), and so does each
  ``sessions.jsonl`` line of ``ebm-eval --experiment``.
"""

from __future__ import annotations

import hashlib
import subprocess
from pathlib import Path
from typing import Any

PROJECT_ROOT = Path(__file__).resolve().parents[1]
"""The folder that holds the project's packages (a checkout's root)."""

SOURCE_PACKAGES = ("ebm_agent", "envs", "baselines", "eval")
"""The packages whose files make the code of a run (the harness included: it builds the agents and scores them)."""

SOURCE_SUFFIXES = (".py", ".yaml")
"""The files that count: code and the configuration tables the code reads."""


class CodeChanged(RuntimeError):
    """The project's source on disk is not the version the sweep started with."""


def source_digest(root: Path = PROJECT_ROOT) -> str:
    """A hash of every source file of ``SOURCE_PACKAGES`` under ``root``, by relative path and content.

    :param root: the folder that holds the packages.
    :return: 16 hex digits.
    """
    digest = hashlib.sha256()
    for package in SOURCE_PACKAGES:
        for path in sorted((root / package).rglob("*")):
            if path.suffix in SOURCE_SUFFIXES and "__pycache__" not in path.parts and path.is_file():
                digest.update(path.relative_to(root).as_posix().encode() + b"\0")
                digest.update(path.read_bytes() + b"\0")
    return digest.hexdigest()[:16]


def _git(root: Path, *args: str) -> str | None:
    """The output of a git command in ``root``, or None where git or the repository is missing."""
    try:
        completed = subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, timeout=30, check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    return completed.stdout if completed.returncode == 0 else None


def read_code_version(root: Path = PROJECT_ROOT) -> dict[str, Any]:
    """The version of the code under ``root`` now.

    :param root: the folder that holds the packages.
    :return: ``{"commit": hex or None, "dirty": bool or None, "source": digest}``; ``commit`` and ``dirty`` are None
        outside a git checkout. Dirty means a tracked file of ``SOURCE_PACKAGES`` differs from the commit or an
        untracked, not ignored one is there.
    """
    commit = _git(root, "rev-parse", "HEAD")
    status = _git(root, "status", "--porcelain", "--", *SOURCE_PACKAGES) if commit is not None else None
    return {
        "commit": commit.strip() if commit else None,
        "dirty": None if status is None else bool(status.strip()),
        "source": source_digest(root),
    }


_pinned: dict[str, Any] | None = None
"""This process's code version once read or handed over."""


def code_version() -> dict[str, Any]:
    """The version of the code this process runs: read the first time it is asked, the same ever after.

    :return: a copy of ``{"commit", "dirty", "source"}`` (see :func:`read_code_version`).
    """
    global _pinned
    if _pinned is None:
        _pinned = read_code_version()
    return dict(_pinned)


def pin_code_version(version: dict[str, Any] | None) -> None:
    """Make ``version`` this process's code version: a sweep's worker takes the version the sweep started with.

    :param version: from :func:`code_version` in the sweep's process (None: forget it; the next
        :func:`code_version` reads the code anew).
    """
    global _pinned
    _pinned = None if version is None else dict(version)


def check_code_unchanged(what: str) -> None:
    """Raise :class:`CodeChanged` when the source on disk is no longer this process's code version.

    :param what: the thing refused, in words, for the message ("run runs/x/particle/ebm/seed_0 not started").
    :raises CodeChanged: naming both versions and what to do.
    """
    expected = code_version()
    found = source_digest()
    if found != expected["source"]:
        raise CodeChanged(
            f"{what}: the project's source changed since this sweep started (source {expected['source']} at commit "
            f"{expected['commit']}, now {found}). A sweep runs one version of the code: let it finish before "
            "changing the library, or stop it and run the same command again (finished runs are kept and skipped)."
        )


__all__ = [
    "PROJECT_ROOT",
    "SOURCE_PACKAGES",
    "CodeChanged",
    "check_code_unchanged",
    "code_version",
    "pin_code_version",
    "read_code_version",
    "source_digest",
]
