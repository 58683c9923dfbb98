"""Shared pytest configuration: force CPU, quiet threads, and make MuJoCo render headless where possible."""

from __future__ import annotations

import ctypes.util
import os

# Headless rendering through OSMesa where the library is installed (`.ci/run` installs libosmesa6). Without it, the
# variables stay unset: with MUJOCO_GL=osmesa and no libOSMesa, importing gymnasium's MuJoCo envs fails outright,
# whereas unset only the render tests skip (the `gl_backend` fixture).
if ctypes.util.find_library("OSMesa"):
    os.environ.setdefault("MUJOCO_GL", "osmesa")
    os.environ.setdefault("PYOPENGL_PLATFORM", "osmesa")

import pytest
import torch

torch.set_num_threads(1)


@pytest.fixture(scope="session")
def gl_backend() -> None:
    """Skip a render test when no MuJoCo GL backend works here (`.ci/run` installs OSMesa for them).

    Without MUJOCO_GL and a display, MuJoCo would try GLFW; its failed renderer leaves an exception in a destructor
    that breaks pytest's teardown on Python 3.11, so the test skips before trying.
    """
    import mujoco

    if not os.environ.get("MUJOCO_GL") and not os.environ.get("DISPLAY"):
        pytest.skip("no headless MuJoCo GL backend: install OSMesa (apt-get install libosmesa6) or set MUJOCO_GL")
    model = mujoco.MjModel.from_xml_string("<mujoco><worldbody><geom size='0.1'/></worldbody></mujoco>")
    try:
        renderer = mujoco.Renderer(model, height=8, width=8)
    except Exception as error:  # any GL failure means "no backend here"
        pytest.skip(f"no working MuJoCo GL backend (MUJOCO_GL={os.environ.get('MUJOCO_GL')}): {error}")
    renderer.close()
