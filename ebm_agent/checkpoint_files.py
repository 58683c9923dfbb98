"""Checkpoint files on disk: atomic writes, integrity checks and the two training-state members.

A checkpoint is SB3's ordinary zip (``data`` + ``*.pth`` state dicts, so ``Agent.load`` reads it) with two extra
members that SB3 ignores: ``training_state.npz`` (replay buffers, noise-generator states; numpy arrays only, read
with ``allow_pickle=False``) and ``training_state.json`` (sizes, positions and numpy bit-generator states). Every
file is written to a temporary name in the target folder and moved into place with ``os.replace``, so a crash
leaves either the old file or the new one, never half of one. See docs/security.md for which loader to trust.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import pathlib
import shutil
import uuid
import zipfile
import zlib
from collections.abc import Iterator
from typing import Any

import numpy as np

STATE_MEMBER = "training_state.npz"
"""Zip member holding the numpy arrays of the training state."""
META_MEMBER = "training_state.json"
"""Zip member holding the scalar training state (sizes, positions, bit-generator states) as JSON."""
INVERSE_STATE_MEMBER = "inverse_model.npz"
"""Zip member of a plain ``save`` holding the arrays of a numpy inverse-dynamics model (RLS); SB3 ignores it."""
INVERSE_META_MEMBER = "inverse_model.json"
"""Zip member of a plain ``save`` holding that model's scalar state as JSON."""
FORMAT_VERSION = 1
"""Version of the two extra members; bumped when their layout changes."""


def zip_path(path: str | pathlib.Path) -> pathlib.Path:
    """The file SB3's ``save`` writes for ``path``: ``.zip`` is appended when the name has no suffix.

    :param path: the path given to ``save``.
    :return: the file path.
    """
    file = pathlib.Path(path)
    return file if file.suffix else pathlib.Path(f"{file}.zip")


@contextlib.contextmanager
def atomic_path(target: str | pathlib.Path) -> Iterator[pathlib.Path]:
    """Yield a temporary path beside ``target``; on success it is synced and renamed onto ``target``.

    On any exception the temporary file is deleted and ``target`` keeps its old content (or stays absent).

    :param target: the final file.
    :return: a context manager yielding the temporary path to write.
    """
    target = pathlib.Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    # Same folder as the target: os.replace is only atomic within one file system.
    temporary = target.with_name(f".{target.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp")
    try:
        yield temporary
        with open(temporary, "rb+") as handle:
            os.fsync(handle.fileno())
        os.replace(temporary, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            temporary.unlink()
        raise


def check_checkpoint_file(path: str | pathlib.Path) -> pathlib.Path:
    """Resolve a saved model's path like SB3 and verify the zip before anything is deserialised.

    Every member's CRC is checked, so a truncated download or a half-copied file is reported here, by name,
    instead of as an error deep inside ``zipfile`` or ``torch.load``.

    :param path: the file (``.zip`` may be omitted).
    :return: the existing file.
    :raises FileNotFoundError: when neither ``path`` nor ``path.zip`` exists.
    :raises ValueError: for a file that is not a complete zip or lacks SB3's ``data`` member.
    """
    file = pathlib.Path(path)
    if not file.is_file() and pathlib.Path(f"{file}.zip").is_file():
        file = pathlib.Path(f"{file}.zip")
    if not file.is_file():
        raise FileNotFoundError(f"No saved model at {path} (nor {path}.zip).")
    try:
        with zipfile.ZipFile(file) as archive:
            broken = archive.testzip()
            names = set(archive.namelist())
    except (zipfile.BadZipFile, zlib.error, EOFError, OSError, ValueError) as error:
        raise corrupted_checkpoint(file, error) from error
    if broken is not None:
        raise corrupted_checkpoint(file, f"member {broken!r} fails its CRC check")
    if "data" not in names:
        raise ValueError(
            f"{file} is a zip but not a saved SB3 model (no 'data' member; it has {sorted(names)[:5]}). Pass the .zip "
            "written by agent.save or agent.save_checkpoint."
        )
    return file


def read_training_state(path: str | pathlib.Path) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """Read the extra members of a checkpoint without unpickling anything (``np.load(allow_pickle=False)``, JSON).

    :param path: a file written by :meth:`CheckpointMixin.save_checkpoint`.
    :return: (arrays by name, metadata).
    :raises ValueError: for a model saved with plain ``save`` or an unreadable training state.
    """
    file = check_checkpoint_file(path)
    with zipfile.ZipFile(file) as archive:
        names = set(archive.namelist())
        if STATE_MEMBER not in names or META_MEMBER not in names:
            raise ValueError(
                f"{file} has no training state: it was written by save(), not save_checkpoint(). Load it with "
                "Agent.load(path, env) (replay buffers then start empty), or resume from a file written by "
                "save_checkpoint / ResumableCheckpointCallback."
            )
        try:
            meta = json.loads(archive.read(META_MEMBER).decode())
            with np.load(io.BytesIO(archive.read(STATE_MEMBER)), allow_pickle=False) as npz:
                arrays = {key: npz[key] for key in npz.files}
        except (ValueError, OSError, zipfile.BadZipFile, EOFError) as error:
            raise corrupted_checkpoint(file, error) from error
    if meta.get("format") != FORMAT_VERSION:
        raise ValueError(
            f"{file} has training-state format {meta.get('format')!r}, this version reads {FORMAT_VERSION}; resume it "
            "with the ebm-agent version that wrote it."
        )
    return arrays, meta


def corrupted_checkpoint(path: Any, cause: Any) -> ValueError:
    """The error for a checkpoint that cannot be read: it names the file, the cause and the way out.

    :param path: the file.
    :param cause: what failed (an exception or a sentence).
    :return: the error to raise.
    """
    return ValueError(
        f"The checkpoint file {path} is truncated or corrupted ({cause}). Use an earlier checkpoint (e.g. the "
        "<prefix>_latest.zip that ResumableCheckpointCallback keeps) or save the model again."
    )


def replace_with_link(source: pathlib.Path, link: pathlib.Path) -> None:
    """Point ``link`` at ``source``'s content atomically (hard link, or a copy where links are unsupported).

    :param source: the existing file.
    :param link: the name to (re)point at it.
    """
    with atomic_path(link) as temporary:
        try:
            os.link(source, temporary)
        except OSError:
            shutil.copyfile(source, temporary)


__all__ = [
    "FORMAT_VERSION",
    "INVERSE_META_MEMBER",
    "INVERSE_STATE_MEMBER",
    "META_MEMBER",
    "STATE_MEMBER",
    "atomic_path",
    "check_checkpoint_file",
    "corrupted_checkpoint",
    "read_training_state",
    "replace_with_link",
    "zip_path",
]
