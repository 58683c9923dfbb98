"""Crash-safe checkpoints for SB3 agents: atomic saves, resumable training state and a weights-only load path.

The mixin gives an agent ``save_checkpoint``, ``load_checkpoint`` and ``load_weights_only``; the file format and its
atomic writes are in ``ebm_agent.checkpoint_files``, the callback that saves during ``learn`` in
``ebm_agent.callbacks``. See docs/security.md for which loader to trust.
"""

from __future__ import annotations

import io
import json
import pathlib
import pickle
import warnings
import zipfile
import zlib
from collections.abc import Iterable
from typing import TYPE_CHECKING, Any, ClassVar, TypeVar

import numpy as np
import torch
from stable_baselines3.common.type_aliases import GymEnv
from stable_baselines3.common.utils import get_device

from ebm_agent.checkpoint_files import (
    FORMAT_VERSION,
    INVERSE_META_MEMBER,
    INVERSE_STATE_MEMBER,
    META_MEMBER,
    STATE_MEMBER,
    atomic_path,
    check_checkpoint_file,
    corrupted_checkpoint,
    read_training_state,
    zip_path,
)

if TYPE_CHECKING:
    from stable_baselines3.common.base_class import BaseAlgorithm

    _MixinBase = BaseAlgorithm
else:
    _MixinBase = object

SelfCheckpointMixin = TypeVar("SelfCheckpointMixin", bound="CheckpointMixin")

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
            buffer = io.BytesIO()  # the extra member is appended to a seekable copy, then the whole zip written out
            super().save(buffer, exclude=exclude, include=include)
            self._append_inverse_model(buffer)
            path.write(buffer.getvalue())
            return
        target = zip_path(path)
        with atomic_path(target) as temporary:
            super().save(temporary, exclude=exclude, include=include)
            self._append_inverse_model(temporary)

    def _append_inverse_model(self, file: pathlib.Path | io.BytesIO) -> None:
        """Add a numpy inverse-dynamics model's fit (RLS) to a saved zip: SB3 only stores torch modules."""
        arrays: dict[str, np.ndarray] = {}
        rest = self._numpy_inverse_state(arrays)
        if rest is None:
            return
        payload = io.BytesIO()
        np.savez(payload, **arrays)  # type: ignore[arg-type]
        with zipfile.ZipFile(file, mode="a") as archive:
            archive.writestr(INVERSE_STATE_MEMBER, payload.getvalue())
            archive.writestr(INVERSE_META_MEMBER, json.dumps(rest, default=_json_default))

    def _numpy_inverse_state(self, arrays: dict[str, np.ndarray]) -> dict[str, Any] | None:
        """The state of a numpy-only inverse model (RLS), its arrays moved into ``arrays``; None for other kinds."""
        inverse = getattr(self, "inverse_model", None)
        # A learned MLP's weights are SB3 torch params already; only a numpy model (RLS) needs storing here.
        if inverse is None or isinstance(getattr(inverse, "module", None), torch.nn.Module):
            return None
        state = inverse.state_dict()
        if state and all(isinstance(v, np.ndarray | int | float | str | bool) or v is None for v in state.values()):
            return _split_state("inverse_model", state, arrays)
        return None

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
            "generator_devices": {},
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
                meta["generator_devices"][name] = generator.device.type
        meta["inverse_model"] = self._numpy_inverse_state(arrays)
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
        else:
            source = io.BytesIO(path.read())  # read once: SB3 and the inverse-model member both need the bytes
        model = cls._load_sb3(source, env, device, custom_objects, print_system_info, force_reset, **kwargs)
        model._restore_inverse_model(source)
        return model

    @classmethod
    def _load_sb3(
        cls: type[SelfCheckpointMixin],
        source: str | pathlib.Path | io.BufferedIOBase,
        env: GymEnv | None,
        device: torch.device | str,
        custom_objects: dict[str, Any] | None,
        print_system_info: bool,
        force_reset: bool,
        **kwargs: Any,
    ) -> SelfCheckpointMixin:
        """SB3's ``load``, its errors translated into ones that name the file and the way out."""
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
                raise corrupted_checkpoint(source, error) from error
            raise
        except (zipfile.BadZipFile, EOFError, zlib.error, pickle.UnpicklingError) as error:
            raise corrupted_checkpoint(source, error) from error
        except RuntimeError as error:
            if "loading state_dict" in str(error):
                raise ValueError(
                    f"{cls.__name__}.load: the networks in {source} do not match the ones these settings build "
                    f"({str(error).splitlines()[0]}). Do not override network or planner settings when loading."
                ) from error
            if "PytorchStreamReader" in str(error) or "zip archive" in str(error):
                raise corrupted_checkpoint(source, error) from error
            raise

    def _restore_inverse_model(self, source: str | pathlib.Path | io.BufferedIOBase) -> None:
        """Put back the numpy inverse model's fit that :meth:`save` appended (nothing when there is none)."""
        inverse = getattr(self, "inverse_model", None)
        if inverse is None or isinstance(getattr(inverse, "module", None), torch.nn.Module):
            return  # nothing to restore, or a learned MLP, whose weights are SB3's torch params
        if isinstance(source, io.IOBase):
            source.seek(0)
        try:
            with zipfile.ZipFile(source) as archive:
                names = set(archive.namelist())
                if INVERSE_STATE_MEMBER not in names or INVERSE_META_MEMBER not in names:
                    return
                rest = json.loads(archive.read(INVERSE_META_MEMBER).decode())
                with np.load(io.BytesIO(archive.read(INVERSE_STATE_MEMBER)), allow_pickle=False) as npz:
                    arrays = {key: npz[key] for key in npz.files}
        except (ValueError, OSError, zipfile.BadZipFile, EOFError, zlib.error) as error:
            raise corrupted_checkpoint(source, error) from error
        inverse.load_state_dict(_join_state("inverse_model", rest, arrays))

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
        saved_devices = meta.get("generator_devices", {})
        for name in meta.get("generators", []):
            generator = getattr(self, name, None)
            if not isinstance(generator, torch.Generator):
                continue
            saved = saved_devices.get(name, generator.device.type)  # older files: as before
            if saved != generator.device.type:
                # A CUDA generator's state (Philox) means nothing to a CPU generator (Mersenne twister) and vice versa.
                warnings.warn(
                    f"{source}: the random generator {name!r} was saved on {saved} and this agent runs on "
                    f"{generator.device.type}; it keeps its fresh seeding, so the resumed run draws other noise than "
                    f"one continued on {saved}. Load with device={saved!r} to resume the same stream.",
                    stacklevel=3,
                )
                continue
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

        The ``*.pth`` state dicts are read with ``torch.load(weights_only=True)``, a numpy inverse model's fit (RLS)
        with ``np.load(allow_pickle=False)`` and JSON; the ``data`` member (cloudpickle) is never deserialised, so a
        shared or downloaded file cannot run code. The hyperparameters are not read
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
                    raise corrupted_checkpoint(source, error) from error
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
        model._restore_inverse_model(source)  # numpy arrays and JSON only, read without pickle
        return model


# ---------------------------------------------------------------------- helpers
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


__all__ = ["CheckpointMixin"]
