"""Fixtures of the Python package's tests (run by ctest: PYTHONPATH holds the build's package,
EXID_SOURCE_DIR the source tree)."""

import os
from pathlib import Path

import numpy as np
import pytest

import exid

SOURCE_DIR = Path(os.environ.get("EXID_SOURCE_DIR", Path(__file__).resolve().parents[2]))


@pytest.fixture(scope="session")
def source_dir() -> Path:
    return SOURCE_DIR


# Robots of the physics checks: two plugins, a URDF file, a DH file with a prismatic joint, and
# a URDF with a coupled transmission (the TX40's motor coordinates).
ROBOTS = {
    "panda": lambda **kw: exid.Robot("panda", **kw),
    "puma560": lambda **kw: exid.Robot("puma560", **kw),
    "puma560_urdf": lambda **kw: exid.Robot(SOURCE_DIR / "robots/puma560/puma560.urdf", **kw),
    "stanford_dh": lambda **kw: exid.Robot(SOURCE_DIR / "robots/stanford/stanford.yaml", **kw),
    "tx40_transmission": lambda **kw: exid.Robot(
        SOURCE_DIR / "data/staubli_tx40/urdf/tx40_mdh_modified.urdf",
        {"extension": str(SOURCE_DIR / "robots/tx40/tx40_exid.xml")},
        **kw,
    ),
}


@pytest.fixture(scope="session", params=sorted(ROBOTS))
def robot_key(request) -> str:
    return request.param


@pytest.fixture(scope="session")
def robot(robot_key) -> exid.Robot:
    return ROBOTS[robot_key]()


@pytest.fixture
def samples(robot):
    return robot.random_samples(50, seed=7)


def smooth_trajectory(robot: exid.Robot, t: np.ndarray):
    """q(t) = q0 + a sin(w t + phase) per joint, with its exact derivatives."""
    rng = np.random.default_rng(3)
    n = robot.dof
    lim = robot.limits
    lo = np.where(np.isfinite(lim["q_min"]), lim["q_min"], -1.0)
    hi = np.where(np.isfinite(lim["q_max"]), lim["q_max"], 1.0)
    q0 = 0.5 * (lo + hi)
    a = 0.25 * (hi - lo) * rng.uniform(0.5, 1.0, n)
    w = rng.uniform(0.5, 2.0, n)
    ph = rng.uniform(0, 2 * np.pi, n)
    arg = np.outer(t, w) + ph
    return q0 + a * np.sin(arg), a * w * np.cos(arg), -a * w * w * np.sin(arg)
