"""Shared pytest configuration: force CPU, quiet threads, and make MuJoCo render headless where possible."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "osmesa")
os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")

import torch

torch.set_num_threads(1)
