"""Where a number came from: a job's fingerprint, a finished run read back, the machine, the command and the time.

- ``job_fingerprint``: a hash of what a job measures, stored in its ``metrics.json``; a run folder whose metrics
  carry the job's fingerprint is a finished run of that job (``completed_result``), so ``ebm-eval --experiment``
  skips it and parts can be run separately into one folder and merge.
- ``provenance.json`` in each run folder (and figure folder): the command that produced it, its part and the date.
- ``sessions.jsonl`` in the results folder: one line per ``ebm-eval --experiment`` invocation (command, machine,
  start, wall time, what ran, what was skipped, what failed).
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import platform
import time
from dataclasses import MISSING, asdict, fields
from pathlib import Path
from typing import Any

import torch

from eval.digest import recorded_hyperparams
from eval.jobs import Job, JobResult, to_plain
from eval.registry import AGENTS

NOT_FINGERPRINTED = ("out_dir", "device", "verbose", "progress_bar", "preset")
"""Job fields that do not change what a run measures (``preset`` does, but only through the agent's settings, which
the defaults digest hashes: a run of the paper preset made before presets existed keeps its fingerprint)."""

PROVENANCE_FILE = "provenance.json"
SESSIONS_FILE = "sessions.jsonl"


def job_fingerprint(job: Job) -> str:
    """A short hash of what the job measures: every field except ``NOT_FINGERPRINTED``, and only fields that differ
    from their default (so adding a field with a default later keeps old runs valid); the hyperparams in the layout
    the recorded runs had (``eval.digest.recorded_hyperparams``), so that moving a setting keeps them valid too.

    :param job: the job.
    :return: 16 hex digits.
    """
    config = to_plain(asdict(job))
    agent_spec = AGENTS.get(job.agent)
    class_name = agent_spec.class_name if agent_spec else None
    config["hyperparams"] = to_plain(recorded_hyperparams(class_name, job.hyperparams))
    kept = {}
    for spec in fields(Job):
        if spec.name in NOT_FINGERPRINTED:
            continue
        if spec.default is not MISSING:
            default = spec.default
        elif spec.default_factory is not MISSING:
            default = spec.default_factory()
        else:
            default = MISSING  # a required field: always kept
        if default is MISSING or config[spec.name] != to_plain(default):
            kept[spec.name] = config[spec.name]
    return hashlib.sha256(json.dumps(kept, sort_keys=True).encode()).hexdigest()[:16]


@functools.lru_cache(maxsize=64)
def _defaults_digest(agent: str, env_id: str, preset: str = "") -> str | None:

    spec = AGENTS.get(agent)
    if spec is None or spec.defaults is None:
        return None
    settings = spec.defaults(env_id, preset)
    return hashlib.sha256(json.dumps(settings, sort_keys=True, default=str).encode()).hexdigest()[:16]


def agent_defaults_digest(agent: str, env_id: str, preset: str = "") -> str | None:
    """A short hash of the settings of one agent on one env under an agent preset (``AgentSpec.defaults``).

    :param agent: a name of ``eval.registry.AGENTS``.
    :param env_id: the env.
    :param preset: ``""`` (the library's defaults) or a preset of ``ebm_agent.presets.PRESETS``.
    :return: 16 hex digits, or None when the agent does not declare its defaults.
    """
    return _defaults_digest(agent, env_id, preset)


def defaults_digest(job: Job) -> str | None:
    """A short hash of the settings the job's agent runs with (``AgentSpec.defaults`` under the job's agent preset):
    what the fingerprint cannot see, since it hashes the job and not the code's defaults (nor the preset, which
    changes only these settings). A pretrained job on a directed
    dataset also depends on the EBM agent that collects it.

    :param job: the job.
    :return: 16 hex digits, or None when the agent does not declare its defaults.
    """
    parts = [_defaults_digest(job.agent, job.env_id, job.preset)]
    if job.mode == "pretrained" and job.dataset != "random":
        parts.append(_defaults_digest("ebm", job.env_id, job.preset))
    if all(part is None for part in parts):
        return None
    return hashlib.sha256("/".join(str(part) for part in parts).encode()).hexdigest()[:16]


def is_current_run(job: Job, metrics: dict[str, Any] | None) -> bool:
    """Whether a run's metrics stand for the job: same fingerprint, and made with today's defaults.

    Runs finished before defaults were recorded carry no digest and are taken as they are.

    :param job: the job.
    :param metrics: the run's ``metrics.json`` (None: no finished run).
    :return: True when the run counts.
    """
    if metrics is None or metrics.get("fingerprint") != job_fingerprint(job):
        return False
    recorded = metrics.get("defaults_digest")
    return recorded is None or recorded == defaults_digest(job)


def completed_result(job: Job) -> JobResult | None:
    """The result of a finished run of this very job, read back from its run folder, or None.

    A run is finished when its ``metrics.json`` parses, carries the job's fingerprint (and, when recorded, today's
    defaults digest) and its ``evaluations.npz`` exists; a run of another configuration, a failed or an interrupted
    run is not.

    :param job: the job.
    :return: the result (status "ok") or None.
    """
    metrics = read_metrics(job.run_dir)
    if metrics is None or not is_current_run(job, metrics):
        return None
    if not (job.run_dir / "evaluations.npz").exists():
        return None
    return JobResult(
        job=job,
        status="ok",
        timesteps=int(metrics["timesteps"]),
        score_mean=float(metrics["score_mean"]),
        score_std=float(metrics["score_std"]),
        episode_scores=tuple(float(s) for s in metrics["episode_scores"]),
        episode_lengths=tuple(int(n) for n in metrics["episode_lengths"]),
        success_rate=metrics.get("success_rate"),
        wall_time_s=float(metrics.get("wall_time_s", 0.0)),
    )


def read_metrics(run_dir: Path) -> dict[str, Any] | None:
    """A run folder's ``metrics.json``, or None when it is missing or unreadable.

    :param run_dir: the run folder.
    :return: the metrics.
    """
    metrics = read_json_dict(Path(run_dir) / "metrics.json")
    required = ("timesteps", "score_mean", "score_std", "episode_scores", "episode_lengths")
    if metrics is None or any(key not in metrics for key in required):
        return None
    return metrics


def machine_info(device: Any = None) -> dict[str, Any]:
    """The machine a run used, for ``metrics.json`` and the results document.

    :param device: the torch device the model ran on (None: not recorded).
    :return: CPU model, logical cores, torch threads, GPU name (None without CUDA), platform and device.
    """

    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    gpu = torch.cuda.get_device_name(0) if torch.cuda.is_available() else None
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "torch_threads": torch.get_num_threads(),
        "gpu": gpu,
        "platform": platform.platform(),
        "device": None if device is None else str(device),
    }


def describe_machine(machine: dict[str, Any] | None) -> str:
    """One line for a ``machine_info`` record: ``"<cpu> (<cores> cores, <threads> torch threads)[, GPU <name>]"``.

    :param machine: the record, or None.
    :return: the line ("unknown" for None).
    """
    if not machine:
        return "unknown"
    text = f"{machine.get('cpu', '?')} ({machine.get('cores', '?')} cores, {machine.get('torch_threads', '?')} torch threads)"
    if machine.get("gpu") and str(machine.get("device", "")).startswith("cuda"):
        text += f", GPU {machine['gpu']}"
    return text


def now() -> str:
    """The local time as ISO 8601 with its UTC offset."""
    return time.strftime("%Y-%m-%dT%H:%M:%S%z")


def write_provenance(folder: Path, command: str, **fields_: Any) -> Path:
    """Write ``provenance.json`` into a run or figure folder.

    :param folder: the folder.
    :param command: the command line that produced its content.
    :param fields_: more JSON-serialisable fields (part, scale, seeds, wall time ...).
    :return: the file.
    """
    path = Path(folder) / PROVENANCE_FILE
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(to_plain({"command": command, "date": now(), **fields_}), indent=2))
    return path


def read_provenance(folder: Path) -> dict[str, Any] | None:
    """A folder's ``provenance.json``, or None.

    :param folder: the folder.
    :return: the record.
    """
    return read_json_dict(Path(folder) / PROVENANCE_FILE)


def read_json_dict(path: Path) -> dict[str, Any] | None:
    """A JSON file holding an object, or None when it is missing, unreadable, torn or holds something else.

    :param path: the file.
    :return: the object.
    """
    try:
        record = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None
    return record if isinstance(record, dict) else None


def append_session(out_dir: Path, record: dict[str, Any]) -> Path:
    """Add one invocation's record to ``<out>/sessions.jsonl``.

    :param out_dir: the results folder.
    :param record: command, machine, start, wall time, parts, ran/skipped/failed run folders.
    :return: the file.
    """
    path = Path(out_dir) / SESSIONS_FILE
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a") as handle:
        handle.write(json.dumps(to_plain(record)) + "\n")
    return path


def read_sessions(out_dir: Path) -> list[dict[str, Any]]:
    """Every record of ``<out>/sessions.jsonl`` (unreadable lines are skipped).

    :param out_dir: the results folder.
    :return: the records, oldest first.
    """
    path = Path(out_dir) / SESSIONS_FILE
    if not path.exists():
        return []
    records = []
    for line in path.read_text().splitlines():
        try:
            record = json.loads(line)
        except ValueError:
            continue
        if isinstance(record, dict):
            records.append(record)
    return records


__all__ = [
    "NOT_FINGERPRINTED",
    "PROVENANCE_FILE",
    "SESSIONS_FILE",
    "agent_defaults_digest",
    "append_session",
    "completed_result",
    "defaults_digest",
    "describe_machine",
    "is_current_run",
    "job_fingerprint",
    "machine_info",
    "now",
    "read_json_dict",
    "read_metrics",
    "read_provenance",
    "read_sessions",
    "write_provenance",
]
