"""Make a package's URDF loadable by PyBullet: resolve ``package://`` paths and add the tool.

The resolved copy is written to a cache directory (``$RAYREACH_CACHE``, else
``$XDG_CACHE_HOME/rayreach``, else ``~/.cache/rayreach``); site-packages is never touched.
"""

from __future__ import annotations

import hashlib
import os
import re
import tempfile
from pathlib import Path

from rayreach.robots.spec import RobotSpec

TOOL_LINK = "rayreach_tool"
"""Cylinder link added on the flange: collides like the rest of the arm."""
TCP_LINK = "rayreach_tcp"
"""Massless link at the tool tip: the end effector, as PyBullet sees it (for tests)."""

_PACKAGE_RE = re.compile(r"package://([^/\"']+)/")


def cache_dir() -> Path:
    root = os.environ.get("RAYREACH_CACHE")
    if root:
        return Path(root)
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "rayreach"


def resolve_packages(text: str, package_dirs: dict[str, Path]) -> str:
    """Replace every ``package://NAME/`` prefix by the absolute directory of NAME."""

    def replace(match: re.Match[str]) -> str:
        name = match.group(1)
        if name not in package_dirs:
            known = ", ".join(sorted(package_dirs)) or "none"
            raise FileNotFoundError(f"URDF refers to package '{name}'; known packages: {known}")
        return str(Path(package_dirs[name]).resolve()) + "/"

    return _PACKAGE_RE.sub(replace, text)


def tool_xml(flange_link: str, length: float, radius: float) -> str:
    """URDF snippet of a cylinder tool along the flange's +z axis and a frame at its tip."""
    half = length / 2.0
    geometry = f'<geometry><cylinder radius="{radius}" length="{length}"/></geometry>'
    inertial = (
        '<inertial><mass value="0.1"/><origin xyz="0 0 0"/>'
        '<inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial>'
    )
    return f"""
  <link name="{TOOL_LINK}">
    {inertial}
    <visual><origin xyz="0 0 {half}"/>{geometry}<material name="rayreach_tool"><color rgba="0.9 0.5 0.1 1"/></material></visual>
    <collision><origin xyz="0 0 {half}"/>{geometry}</collision>
  </link>
  <joint name="{TOOL_LINK}_joint" type="fixed">
    <parent link="{flange_link}"/><child link="{TOOL_LINK}"/><origin xyz="0 0 0" rpy="0 0 0"/>
  </joint>
  <link name="{TCP_LINK}">{inertial}</link>
  <joint name="{TCP_LINK}_joint" type="fixed">
    <parent link="{TOOL_LINK}"/><child link="{TCP_LINK}"/><origin xyz="0 0 {length}" rpy="0 0 0"/>
  </joint>
"""


def resolved_urdf(spec: RobotSpec) -> Path:
    """Path of a loadable copy of the robot's URDF with meshes resolved and the tool added."""
    source = spec.urdf()
    if not source.is_file():
        raise FileNotFoundError(
            f"URDF of robot '{spec.name}' not found at {source}; is its model package installed?"
        )
    text = resolve_packages(source.read_text(), spec.package_dirs())
    if "</robot>" not in text:
        raise ValueError(f"{source} is not a URDF: no </robot> tag")
    text = text.replace("</robot>", tool_xml(spec.flange_link, spec.tool.length, spec.tool.radius) + "</robot>")
    digest = hashlib.sha1(text.encode()).hexdigest()[:12]
    target = cache_dir() / "urdf" / f"{spec.name}-{digest}.urdf"
    if not target.exists():
        target.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=target.parent, suffix=".urdf")
        with os.fdopen(fd, "w") as handle:
            handle.write(text)
        os.replace(tmp, target)  # atomic: parallel workers never see a half-written file
    return target
