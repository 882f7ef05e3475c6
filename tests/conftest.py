"""Shared fixtures: one PyBullet scene per robot for the whole session (loading costs ~0.25 s)."""

from __future__ import annotations

import numpy as np
import pytest

from rayreach.sim.kinematics import Kinematics
from rayreach.robots import get_robot
from rayreach.sim.scene import Scene
from rayreach.sim.sensors import RayModel

ROBOTS = ("ur5", "kr16", "ur10")


class RobotRig:
    """A robot's spec, kinematics, ray model and a PyBullet scene at its default base pose."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.spec = get_robot(name)
        self.kin = Kinematics(self.spec)
        self.scene = Scene(self.spec)
        self.rays = RayModel(self.spec)

    def random_q(self, rng: np.random.Generator, clip_pi: bool = False) -> np.ndarray:
        """Uniform within the joint limits (optionally within [-pi, pi] as well)."""
        low, high = self.kin.lower, self.kin.upper
        if clip_pi:
            low, high = np.maximum(low, -np.pi), np.minimum(high, np.pi)
        return rng.uniform(low, high)


@pytest.fixture(scope="session")
def rigs():
    made = {name: RobotRig(name) for name in ROBOTS}
    yield made
    for rig in made.values():
        rig.scene.close()


@pytest.fixture(params=ROBOTS)
def rig(request, rigs):
    """Each robot in turn; its scene is emptied of obstacles before and after the test."""
    r = rigs[request.param]
    r.scene.set_obstacles([])
    yield r
    r.scene.set_obstacles([])
