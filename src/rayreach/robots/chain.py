"""A robot's joint chain as the kinematics computes it, from a DH table or from the URDF.

Joint ``i`` moves frame ``i - 1`` to frame ``i`` by ``before_i @ Rot(axis_i, q_i) @ after_i``:
a fixed transform, a turn about a unit axis by the joint value, another fixed transform.
A URDF joint is its ``<origin>`` then its ``<axis>`` (``after`` the identity, but for the
fixed joints down to the flange after the last one); a standard DH row (paper eq. 2) is
``Rz(offset)``, a turn about ``sign * z``, then ``Tz(d) Tx(a) Rx(alpha)``. One form serves
both, so the compiled forward kinematics and IK (``rayreach.sim.ik_kernel``) know no DH.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rayreach.robots.spec import DHTable, RobotSpec
from rayreach.sim.transforms import pose_matrix, rpy_to_matrix

MOVING_TYPES = ("revolute", "continuous")
"""URDF joint types a chain may move; ``fixed`` joints fold into their neighbours."""


@dataclass(frozen=True, eq=False)
class JointChain:
    """Per joint a fixed transform, a unit axis and another fixed transform; ``root`` takes the
    URDF's root link to frame 0 (the DH base rotation, or the identity)."""

    before: np.ndarray
    """(n, 4, 4)"""
    axis: np.ndarray
    """(n, 3), unit vectors in the joint's frame after ``before``."""
    after: np.ndarray
    """(n, 4, 4)"""
    root: np.ndarray
    """(4, 4)"""

    @property
    def n_joints(self) -> int:
        return len(self.axis)

    def key(self) -> bytes:
        """The chain's numbers as bytes, for caches of what depends on the arm's geometry."""
        return b"".join(np.ascontiguousarray(a).tobytes() for a in (self.before, self.axis, self.after, self.root))


def dh_chain(dh: DHTable, base_rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> JointChain:
    """The chain of a standard DH table: ``Rz(sign q + offset) Tz(d) Tx(a) Rx(alpha)`` per row."""
    n = len(dh.d)
    before = np.tile(np.eye(4), (n, 1, 1))
    after = np.tile(np.eye(4), (n, 1, 1))
    for i in range(n):
        before[i, :3, :3] = rpy_to_matrix((0.0, 0.0, dh.offset[i]))
        ca, sa = math.cos(dh.alpha[i]), math.sin(dh.alpha[i])
        after[i, :3, :] = [[1.0, 0.0, 0.0, dh.a[i]], [0.0, ca, -sa, 0.0], [0.0, sa, ca, dh.d[i]]]
    axis = np.zeros((n, 3))
    axis[:, 2] = dh.sign
    return JointChain(before=before, axis=axis, after=after, root=pose_matrix((0.0, 0.0, 0.0), rpy_to_matrix(base_rpy)))


def _floats(text: str | None, default: str, what: str) -> tuple[float, ...]:
    values = tuple(float(v) for v in (text or default).split())
    if len(values) != 3:
        raise ValueError(f"{what}: expected 3 numbers, got {text!r}")
    return values


def _origin(joint: ET.Element) -> np.ndarray:
    element = joint.find("origin")
    name = joint.get("name")
    xyz = _floats(None if element is None else element.get("xyz"), "0 0 0", f"joint '{name}' origin xyz")
    rpy = _floats(None if element is None else element.get("rpy"), "0 0 0", f"joint '{name}' origin rpy")
    return pose_matrix(xyz, rpy_to_matrix(rpy))


def urdf_chain(urdf: str | Path, joint_names: tuple[str, ...], tip_link: str, base_link: str | None = None) -> JointChain:
    """The chain from ``base_link`` (frame 0; None: the URDF's root link) to ``tip_link`` (frame
    n: the flange), read from the joints' ``<origin>`` and ``<axis>``; the moving joints on the
    way must be ``joint_names``, in that order, and only fixed joints may lie between the root
    and ``base_link`` (they make the chain's ``root``). ``urdf`` is a path, or the XML text itself."""
    text = urdf if isinstance(urdf, str) and urdf.lstrip().startswith("<") else Path(urdf).read_text()
    root = ET.fromstring(text)
    joints = {j.find("child").get("link"): j for j in root.findall("joint")}  # <robot>'s own, not transmissions'
    links = {link.get("name") for link in root.findall("link")}
    if tip_link not in links:
        raise ValueError(f"URDF has no link '{tip_link}'; links: {', '.join(sorted(links))}")
    path: list[ET.Element] = []
    link = tip_link
    while link in joints:
        path.append(joints[link])
        link = joints[link].find("parent").get("link")
    path.reverse()
    base = np.eye(4)
    if base_link is not None and base_link != link:
        children = [j.find("child").get("link") for j in path]
        if base_link not in children:
            raise ValueError(f"link '{base_link}' is not on the way from the URDF's root '{link}' to '{tip_link}'")
        above, path = path[:children.index(base_link) + 1], path[children.index(base_link) + 1:]
        for j in above:
            if j.get("type") != "fixed":
                raise ValueError(f"joint '{j.get('name')}' ({j.get('type')}) lies between the URDF's root '{link}' "
                                 f"and the base link '{base_link}'; only fixed joints may")
            base = base @ _origin(j)
        link = base_link
    for j in path:
        if j.get("type") not in MOVING_TYPES + ("fixed",):
            raise ValueError(f"joint '{j.get('name')}' is {j.get('type')}; a chain takes "
                             f"{', '.join(MOVING_TYPES)} or fixed joints")
    moving = [j for j in path if j.get("type") in MOVING_TYPES]
    names = tuple(j.get("name") for j in moving)
    if names != tuple(joint_names):
        raise ValueError(f"the URDF's moving joints from '{link}' to '{tip_link}' are {names}; the spec names "
                         f"{tuple(joint_names)}")
    n = len(moving)
    before, after, axis = np.empty((n, 4, 4)), np.tile(np.eye(4), (n, 1, 1)), np.empty((n, 3))
    pending, index = np.eye(4), 0
    for j in path:
        pending = pending @ _origin(j)
        if j.get("type") in MOVING_TYPES:
            element = j.find("axis")
            a = np.array(_floats(None if element is None else element.get("xyz"), "1 0 0",
                                 f"joint '{j.get('name')}' axis"))
            if np.linalg.norm(a) < 1e-9:
                raise ValueError(f"joint '{j.get('name')}' has a zero axis")
            before[index], axis[index] = pending, a / np.linalg.norm(a)
            pending, index = np.eye(4), index + 1
    after[-1] = pending  # fixed joints from the last moving joint to the flange
    return JointChain(before=before, axis=axis, after=after, root=base)


_CHAINS: dict[tuple, JointChain] = {}


def robot_chain(spec: RobotSpec) -> JointChain:
    """The spec's chain: its DH table when it has one (the paper's two robots), else its URDF's
    joints from ``base_link`` to ``flange_link``; read once per robot and URDF."""
    if spec.dh is not None:
        return dh_chain(spec.dh, spec.dh_base_rpy)
    source = spec.urdf()
    key = (spec.name, str(source), spec.joint_names, spec.base_link, spec.flange_link)
    if key not in _CHAINS:
        if not source.is_file():
            raise FileNotFoundError(f"URDF of robot '{spec.name}' not found at {source}; is its model package "
                                    "installed?")
        _CHAINS[key] = urdf_chain(source, spec.joint_names, spec.flange_link, spec.base_link)
    return _CHAINS[key]
