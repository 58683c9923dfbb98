"""``ebm-eval``: the comparison harness that pits the EBM planning agent against its baselines.

Runs are independent ``Job``s (env, agent, seed, budget) that ``run_job`` executes and an ``Executor``
schedules; ``eval.report`` and ``eval.plots`` turn the ``JobResult``s into tables and figures. Agents are
imported lazily by the factories of ``eval.registry.AGENTS``, so importing this package needs none of them.
"""

from __future__ import annotations

from eval.executors import Executor, LocalExecutor, executor_from_name
from eval.jobs import Job, JobResult
from eval.registry import AGENTS, AgentSpec, get_agent, register_agent
from eval.run import run_job

__all__ = [
    "AGENTS",
    "AgentSpec",
    "Executor",
    "Job",
    "JobResult",
    "LocalExecutor",
    "executor_from_name",
    "get_agent",
    "register_agent",
    "run_job",
]
