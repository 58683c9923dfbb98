"""Crash-safe checkpoints for SB3 agents: atomic saves, resumable training state and a weights-only load path.

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
import pickle
import uuid
import zipfile
import zlib
from collections.abc import Iterable, Iterator
from typing import TYPE_CHECKING, Any, ClassVar, TypeVar

import numpy as np
import torch
from stable_baselines3.common.callbacks import CheckpointCallback
from stable_baselines3.common.type_aliases import GymEnv
from stable_baselines3.common.utils import get_device

if TYPE_CHECKING:
    from stable_baselines3.common.base_class import BaseAlgorithm

    _MixinBase = BaseAlgorithm
else:
    _MixinBase = object

SelfCheckpointMixin = TypeVar("SelfCheckpointMixin", bound="CheckpointMixin")

STATE_MEMBER = "training_state.npz"
"""Zip member holding the numpy arrays of the training state."""
META_MEMBER = "training_state.json"
"""Zip member holding the scalar training state (sizes, positions, bit-generator states) as JSON."""
FORMAT_VERSION = 1
"""Version of the two extra members; bumped when their layout changes."""
_NOT_STATE_DICTS = ("pytorch_variables.pth", "tensors.pth")  # SB3's torch variables, not module/optimiser states


class CheckpointMixin(_MixinBase):
    """Atomic ``save``, resumable ``save_checkpoint``/``load_checkpoint``, clear load errors and ``load_weights_only``.

    Put it first in the bases of an SB3 algorithm (``class Agent(CheckpointMixin, BaseAlgorithm)``). The training
    state it adds to a checkpoint is found by name: the replay buffers listed in ``checkpoint_buffers`` (objects
    with ``state_dict``/``load_state_dict`` of numpy arrays and plain values), the ``torch.Generator`` attributes in
    ``checkpoint_generators``, and a numpy-only inverse-dynamics model (RLS); the optimiser state is already in
    SB3's zip. Attributes an agent does not have are skipped.
    """

    checkpoint_buffers: ClassVar[tuple[str, ...]] = ("pos_buffer", "neg_buffer")
    checkpoint_generators: ClassVar[tuple[str, ...]] = ("_generator",)

    # ------------------------------------------------------------------ writing
    def save(
        self,
        path: str | pathlib.Path | io.BufferedIOBase,
        exclude: Iterable[str] | None = None,
        include: Iterable[str] | None = None,
    ) -> None:
        """Save the agent in SB3's zip format, atomically: an existing file is replaced only by a complete new one.

        :param path: target file (``.zip`` is appended when it has no suffix, as SB3 does) or an open binary file
            (written directly; atomicity is then the caller's business).
        :param exclude: attributes to leave out in addition to the default ones.
        :param include: attributes to save although excluded by default.
        :raises FloatingPointError: when a network holds NaN/inf weights (nothing is written).
        """
        self._check_finite_weights("save")
        if isinstance(path, io.IOBase):
            super().save(path, exclude=exclude, include=include)
            return
        target = zip_path(path)
        with atomic_path(target) as temporary:
            super().save(temporary, exclude=exclude, include=include)

    def save_checkpoint(self, path: str | pathlib.Path) -> pathlib.Path:
        """Save everything ``learn`` needs to resume: the SB3 zip plus replay buffers and generator states, atomically.

        :param path: target file (``.zip`` appended when it has no suffix).
        :return: the path written.
        :raises FloatingPointError: when a network holds NaN/inf weights (the previous file is left untouched).
        """
        self._check_finite_weights("save_checkpoint")
        arrays, meta = self._training_state()
        payload = io.BytesIO()
        np.savez(payload, **arrays)  # type: ignore[arg-type]  # (numpy stubs type the kwargs as its own flags)
        target = zip_path(path)
        with atomic_path(target) as temporary:
            super().save(temporary)
            with zipfile.ZipFile(temporary, mode="a") as archive:
                archive.writestr(STATE_MEMBER, payload.getvalue())
                archive.writestr(META_MEMBER, json.dumps(meta, default=_json_default))
        return target

    def _get_torch_save_params(self) -> tuple[list[str], list[str]]:
        state_dicts, variables = super()._get_torch_save_params()
        # A resumed run needs the optimiser's moments too; SB3's default lists only "policy".
        if getattr(getattr(self, "policy", None), "optimizer", None) is not None and "policy.optimizer" not in state_dicts:
            state_dicts = [*state_dicts, "policy.optimizer"]
        return state_dicts, variables

    def _check_finite_weights(self, action: str) -> None:
        """Refuse to write a model whose networks diverged, so the last good file on disk survives."""
        for name in self._get_torch_save_params()[0]:
            module = _get_attribute(self, name)
            if not isinstance(module, torch.nn.Module):
                continue
            for key, tensor in module.state_dict().items():
                if tensor.is_floating_point() and not bool(torch.isfinite(tensor).all()):
                    raise FloatingPointError(
                        f"{type(self).__name__}.{action}: {name}.{key} holds NaN or inf (training diverged before "
                        f"timestep {self.num_timesteps}); nothing was written, so the previous file is intact. Resume "
                        "from the last checkpoint with a lower learning_rate."
                    )

    def _training_state(self) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
        """Split the resumable state into numpy arrays (npz) and plain values (JSON)."""
        arrays: dict[str, np.ndarray] = {}
        meta: dict[str, Any] = {
            "format": FORMAT_VERSION,
            "class": type(self).__name__,
            "num_timesteps": int(self.num_timesteps),
            "buffers": {},
            "generators": [],
            "inverse_model": None,
        }
        for name in self.checkpoint_buffers:
            buffer = getattr(self, name, None)
            if buffer is not None:
                meta["buffers"][name] = _split_state(name, buffer.state_dict(), arrays)
        for name in self.checkpoint_generators:
            generator = getattr(self, name, None)
            if isinstance(generator, torch.Generator):
                arrays[f"{name}.state"] = generator.get_state().numpy()
                meta["generators"].append(name)
        inverse = getattr(self, "inverse_model", None)
        # A learned MLP's weights are SB3 torch params already; only a numpy model (RLS) needs storing here.
        if inverse is not None and not isinstance(getattr(inverse, "module", None), torch.nn.Module):
            state = inverse.state_dict()
            if state and all(isinstance(v, np.ndarray | int | float | str | bool) or v is None for v in state.values()):
                meta["inverse_model"] = _split_state("inverse_model", state, arrays)
        return arrays, meta

    # ------------------------------------------------------------------ reading
    @classmethod
    def load(  # type: ignore[override]
        cls: type[SelfCheckpointMixin],
        path: str | pathlib.Path | io.BufferedIOBase,
        env: GymEnv | None = None,
        device: torch.device | str = "auto",
        custom_objects: dict[str, Any] | None = None,
        print_system_info: bool = False,
        force_reset: bool = True,
        **kwargs: Any,
    ) -> SelfCheckpointMixin:
        """SB3's ``load`` with clear errors for a truncated/corrupted file and for an env with other spaces.

        This unpickles the ``data`` member (cloudpickle), which can run code: load only files you wrote or trust.
        For a shared model use :meth:`load_weights_only`.

        :param path: the zip (``.zip`` may be omitted) or an open binary file.
        :param env: the env to run on (must have the spaces the model was trained on), or None for predict only.
        :param device: torch device.
        :param custom_objects: SB3's replacements for attributes that cannot be unpickled.
        :param print_system_info: print the saving and the current system info.
        :param force_reset: reset the env before the next ``learn``.
        :param kwargs: attributes to override after loading.
        :return: the loaded agent.
        :raises FileNotFoundError: when there is no such file.
        :raises ValueError: for a truncated/corrupted file or mismatched spaces.
        """
        source: str | pathlib.Path | io.BufferedIOBase = path
        if not isinstance(path, io.IOBase):
            source = check_checkpoint_file(path)
        try:
            return super().load(  # type: ignore[misc]
                source,
                env=env,
                device=device,
                custom_objects=custom_objects,
                print_system_info=print_system_info,
                force_reset=force_reset,
                **kwargs,
            )
        except ValueError as error:
            message = str(error)
            if message.startswith(("Observation spaces do not match", "Action spaces do not match")):
                raise ValueError(
                    f"{cls.__name__}.load: {source} was trained on an env with other spaces than the env passed "
                    f"({message}; the first is the saved one). Pass the env it was trained on (same id and constructor "
                    "options), or train a new agent on this env."
                ) from error
            if isinstance(error, json.JSONDecodeError) or "wasn't a zip-file" in message:
                raise _corrupted(source, error) from error
            raise
        except (zipfile.BadZipFile, EOFError, zlib.error, pickle.UnpicklingError) as error:
            raise _corrupted(source, error) from error
        except RuntimeError as error:
            if "loading state_dict" in str(error):
                raise ValueError(
                    f"{cls.__name__}.load: the networks in {source} do not match the ones these settings build "
                    f"({str(error).splitlines()[0]}). Do not override network or planner settings when loading."
                ) from error
            if "PytorchStreamReader" in str(error) or "zip archive" in str(error):
                raise _corrupted(source, error) from error
            raise

    @classmethod
    def load_checkpoint(
        cls: type[SelfCheckpointMixin],
        path: str | pathlib.Path,
        env: GymEnv | None = None,
        device: torch.device | str = "auto",
        **kwargs: Any,
    ) -> SelfCheckpointMixin:
        """Load a :meth:`save_checkpoint` file with its replay buffers and generators, ready to resume ``learn``.

        Continue with ``agent.learn(total - agent.num_timesteps, reset_num_timesteps=False, tb_log_name=name)``: the
        step counter goes on from the checkpoint and SB3 writes into the same TensorBoard run folder. Like
        :meth:`load` this unpickles SB3's ``data``: use it on your own checkpoints.

        :param path: the checkpoint.
        :param env: the env to continue on (same spaces).
        :param device: torch device.
        :param kwargs: passed to :meth:`load`.
        :return: the agent.
        :raises ValueError: for a file without training state (written by ``save``), a corrupted file, or
            mismatched spaces/buffer sizes.
        """
        source = check_checkpoint_file(path)
        arrays, meta = read_training_state(source)
        if meta.get("class") != cls.__name__:
            raise ValueError(
                f"{source} is a checkpoint of {meta.get('class')}, not {cls.__name__}: load it with "
                f"{meta.get('class')}.load_checkpoint."
            )
        model = cls.load(source, env=env, device=device, **kwargs)
        model._restore_training_state(arrays, meta, source)
        return model

    def _restore_training_state(self, arrays: dict[str, np.ndarray], meta: dict[str, Any], source: pathlib.Path) -> None:
        for name, entries in meta.get("buffers", {}).items():
            buffer = getattr(self, name, None)
            if buffer is None:
                raise ValueError(f"{source} holds a replay buffer {name!r} that {type(self).__name__} does not have.")
            buffer.load_state_dict(_join_state(name, entries, arrays))
        for name in meta.get("generators", []):
            generator = getattr(self, name, None)
            if isinstance(generator, torch.Generator):
                generator.set_state(torch.from_numpy(arrays[f"{name}.state"].copy()))
        inverse = getattr(self, "inverse_model", None)
        if meta.get("inverse_model") is not None and inverse is not None:
            inverse.load_state_dict(_join_state("inverse_model", meta["inverse_model"], arrays))

    @classmethod
    def load_weights_only(
        cls: type[SelfCheckpointMixin],
        path: str | pathlib.Path,
        env: GymEnv | str,
        policy: str = "MultiInputPolicy",
        device: torch.device | str = "auto",
        **hyperparams: Any,
    ) -> SelfCheckpointMixin:
        """Build a fresh agent and load only the tensors of a saved model: no pickled Python object is read.

        The ``*.pth`` state dicts are read with ``torch.load(weights_only=True)``; the ``data`` member (cloudpickle)
        is never deserialised, so a shared or downloaded file cannot run code. The hyperparameters are not read
        from the file either: pass the ones the model was trained with (network sizes, inverse dynamics, ...).
        The step counter and replay buffers start from zero.

        :param path: the zip written by ``save`` or ``save_checkpoint``.
        :param env: the env (or its id) that fixes the spaces.
        :param policy: the policy alias.
        :param device: torch device.
        :param hyperparams: constructor arguments of the agent.
        :return: the agent with the saved weights (and optimiser state).
        :raises ValueError: for a corrupted file, a member that is not plain tensors, or state dicts whose names,
            keys or shapes differ from the ones these hyperparameters build.
        """
        source = check_checkpoint_file(path)
        model = cls(policy, env, device=device, **hyperparams)  # type: ignore[call-arg]
        expected = set(model._get_torch_save_params()[0])
        params: dict[str, Any] = {}
        with zipfile.ZipFile(source) as archive:
            members = [n for n in archive.namelist() if n.endswith(".pth") and n not in _NOT_STATE_DICTS]
            found = {member[: -len(".pth")] for member in members}
            if found != expected:
                raise ValueError(
                    f"{cls.__name__}.load_weights_only: {source} holds the state dicts {sorted(found)}, these "
                    f"hyperparameters build {sorted(expected)}. Pass the settings the model was trained with (e.g. "
                    "the same inverse_dynamics)."
                )
            for member in members:
                try:
                    params[member[: -len(".pth")]] = torch.load(
                        io.BytesIO(archive.read(member)), map_location=get_device(device), weights_only=True
                    )
                except pickle.UnpicklingError as error:
                    raise ValueError(
                        f"{cls.__name__}.load_weights_only: {source}:{member} holds more than tensors, so the weights-only "
                        f"reader refused it ({str(error).splitlines()[0]}). It was not written by SB3's save, or was "
                        "tampered with: do not open it with load()."
                    ) from error
                except (EOFError, RuntimeError, zlib.error, zipfile.BadZipFile) as error:
                    raise _corrupted(source, error) from error
        for name in expected:
            module = _get_attribute(model, name)
            if isinstance(module, torch.nn.Module):
                _check_state_dict(module.state_dict(), params[name], f"{source}:{name}")
        try:
            model.set_parameters(params, exact_match=True, device=device)
        except (ValueError, RuntimeError, KeyError) as error:
            raise ValueError(
                f"{cls.__name__}.load_weights_only: the optimiser state in {source} does not fit these settings "
                f"({error}). Pass the settings the model was trained with."
            ) from error
        return model


class ResumableCheckpointCallback(CheckpointCallback):
    """Save a resumable checkpoint every ``save_freq`` callback calls and keep ``<prefix>_latest.zip`` pointing at it.

    Each checkpoint is ``<save_path>/<prefix>_<num_timesteps>_steps.zip`` (written atomically by
    :meth:`CheckpointMixin.save_checkpoint`); ``<prefix>_latest.zip`` is then replaced atomically by a hard link
    to it (a copy where links are not supported). A run killed at any moment leaves the latest checkpoint whole.
    Resume with ``Agent.load_checkpoint(callback.latest_path, env)``.

    :param save_freq: callback calls between checkpoints (one call per vectorised env step, i.e. ``n_envs``
        transitions, as SB3's ``CheckpointCallback``).
    :param save_path: folder of the checkpoints (created if needed).
    :param name_prefix: file name prefix.
    :param keep_last: number of numbered checkpoints to keep (older ones are deleted); None keeps all.
    :param verbose: 2 prints each save.
    """

    def __init__(
        self,
        save_freq: int,
        save_path: str | pathlib.Path,
        name_prefix: str = "checkpoint",
        keep_last: int | None = None,
        verbose: int = 0,
    ) -> None:
        if isinstance(save_freq, bool) or not isinstance(save_freq, int | np.integer) or save_freq < 1:
            raise ValueError(f"save_freq must be a positive int (callback calls between checkpoints), got {save_freq!r}.")
        if keep_last is not None and (isinstance(keep_last, bool) or not isinstance(keep_last, int) or keep_last < 1):
            raise ValueError(f"keep_last must be None (keep every checkpoint) or an int >= 1, got {keep_last!r}.")
        super().__init__(int(save_freq), str(save_path), name_prefix=name_prefix, verbose=verbose)
        self.keep_last = keep_last
        self.latest_path = pathlib.Path(save_path) / f"{name_prefix}_latest.zip"
        self.saved_paths: list[pathlib.Path] = []

    def _init_callback(self) -> None:
        super()._init_callback()
        if not callable(getattr(self.model, "save_checkpoint", None)):
            raise TypeError(
                f"ResumableCheckpointCallback needs an agent with save_checkpoint (CheckpointMixin); "
                f"{type(self.model).__name__} has none. Use SB3's CheckpointCallback(save_replay_buffer=True) for it."
            )

    def _on_step(self) -> bool:
        if self.n_calls % self.save_freq == 0:
            path = self.model.save_checkpoint(self._checkpoint_path(extension="zip"))  # type: ignore[attr-defined]
            _replace_with_link(path, self.latest_path)
            self.saved_paths.append(path)
            if self.keep_last is not None:
                while len(self.saved_paths) > self.keep_last:
                    with contextlib.suppress(FileNotFoundError):
                        self.saved_paths.pop(0).unlink()
            if self.verbose >= 2:
                print(f"Saving resumable checkpoint to {path}")
        return True


def latest_checkpoint(save_path: str | pathlib.Path, name_prefix: str = "checkpoint") -> pathlib.Path | None:
    """The ``<prefix>_latest.zip`` a :class:`ResumableCheckpointCallback` keeps, if one was written.

    :param save_path: the callback's folder.
    :param name_prefix: the callback's prefix.
    :return: the path, or None when no checkpoint was saved yet.
    """
    path = pathlib.Path(save_path) / f"{name_prefix}_latest.zip"
    return path if path.is_file() else None


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
        raise _corrupted(file, error) from error
    if broken is not None:
        raise _corrupted(file, f"member {broken!r} fails its CRC check")
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
            raise _corrupted(file, error) from error
    if meta.get("format") != FORMAT_VERSION:
        raise ValueError(
            f"{file} has training-state format {meta.get('format')!r}, this version reads {FORMAT_VERSION}; resume it "
            "with the ebm-agent version that wrote it."
        )
    return arrays, meta


# ---------------------------------------------------------------------- helpers
def _corrupted(path: Any, cause: Any) -> ValueError:
    return ValueError(
        f"The checkpoint file {path} is truncated or corrupted ({cause}). Use an earlier checkpoint (e.g. the "
        "<prefix>_latest.zip that ResumableCheckpointCallback keeps) or save the model again."
    )


def _split_state(prefix: str, state: dict[str, Any], arrays: dict[str, np.ndarray]) -> dict[str, Any]:
    """Move the array values of ``state`` into ``arrays`` under ``prefix.key``; return the rest (JSON-able)."""
    rest: dict[str, Any] = {}
    for key, value in state.items():
        if isinstance(value, np.ndarray):
            arrays[f"{prefix}.{key}"] = value
        else:
            rest[key] = value
    return rest


def _join_state(prefix: str, rest: dict[str, Any], arrays: dict[str, np.ndarray]) -> dict[str, Any]:
    state = dict(rest)
    for name, value in arrays.items():
        if name.startswith(f"{prefix}."):
            state[name[len(prefix) + 1 :]] = value
    return state


def _json_default(value: Any) -> Any:
    if isinstance(value, np.integer | np.floating | np.bool_):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"cannot store {type(value).__name__} in a checkpoint's JSON training state")


def _get_attribute(obj: Any, dotted: str) -> Any:
    for part in dotted.split("."):
        obj = getattr(obj, part, None)
    return obj


def _check_state_dict(mine: dict[str, torch.Tensor], saved: Any, where: str) -> None:
    """Names and shapes of a saved module state dict must be the ones this model has."""
    if not isinstance(saved, dict):
        raise ValueError(f"{where} is not a state dict (got {type(saved).__name__}).")
    missing, unexpected = sorted(set(mine) - set(saved)), sorted(set(saved) - set(mine))
    shapes = [
        f"{key}: saved {tuple(saved[key].shape)}, built {tuple(mine[key].shape)}"
        for key in mine
        if key in saved and (not isinstance(saved[key], torch.Tensor) or saved[key].shape != mine[key].shape)
    ]
    if missing or unexpected or shapes:
        raise ValueError(
            f"{where} does not fit the networks these hyperparameters build (missing {missing[:4]}, unexpected "
            f"{unexpected[:4]}, shapes {shapes[:4]}). Pass the network settings the model was trained with (e.g. "
            "energy={'hidden_dim': ...})."
        )


def _replace_with_link(source: pathlib.Path, link: pathlib.Path) -> None:
    """Point ``link`` at ``source``'s content atomically (hard link, or a copy where links are unsupported)."""
    temporary = link.with_name(f".{link.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp")
    try:
        try:
            os.link(source, temporary)
        except OSError:
            with open(source, "rb") as reader, open(temporary, "wb") as writer:
                while chunk := reader.read(1 << 20):
                    writer.write(chunk)
                writer.flush()
                os.fsync(writer.fileno())
        os.replace(temporary, link)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            temporary.unlink()
        raise


__all__ = [
    "CheckpointMixin",
    "ResumableCheckpointCallback",
    "atomic_path",
    "check_checkpoint_file",
    "latest_checkpoint",
    "read_training_state",
    "zip_path",
]
