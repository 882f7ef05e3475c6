"""One memory of what the rays saw in an episode, with the views the layers read.

The rays see 0.4 m and the arm passes what they saw a moment ago: every layer that keeps
the arm off an obstacle needs the past scans, but each reads them its own way. The ray
shield holds off the near hits of the last few scans, wherever the tool is now; the arm's
rule keeps the blind links off the hits of the last hundred steps in which the arm moved
(a held arm would otherwise forget what holds it); the detour plans round everything seen
in the episode. All three are views of one list of scans, kept here.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from rayreach.env.perception import Perception


class Scan:
    """One step's perception, and whether the step that led to it moved the arm (an
    episode's first scan counts as moved). Views computed from it are kept with it."""

    __slots__ = ("perception", "moved", "_views")

    def __init__(self, perception: Perception, moved: bool) -> None:
        self.perception = perception
        self.moved = moved
        self._views: dict = {}

    def view(self, key: object, compute: Callable[[Perception], object]) -> object:
        """``compute(perception)``, computed once per ``key``."""
        if key not in self._views:
            self._views[key] = compute(self.perception)
        return self._views[key]


class RayMemory:
    """Every scan of the episode, oldest first; the newest is the current perception."""

    def __init__(self) -> None:
        self.scans: list[Scan] = []
        self._moving: list[int] = []  # indices of the scans after a move
        self._points: tuple[int, int, np.ndarray] | None = None

    def add(self, perception: Perception, moved: bool) -> None:
        """Remember the scan taken after a step (``moved``: the arm moved in it)."""
        if moved:
            self._moving.append(len(self.scans))
        self.scans.append(Scan(perception, moved))

    @property
    def now(self) -> Perception:
        """The current perception (the newest scan)."""
        return self.scans[-1].perception

    def before(self, steps: int) -> list[Scan]:
        """The last ``steps`` scans before the current one, oldest first (the ray shield's view)."""
        steps = int(steps)
        return self.scans[max(0, len(self.scans) - 1 - steps):-1] if steps > 0 else []

    def seen_points(self, steps: int) -> np.ndarray:
        """The world points the rays hit (and the arm's rays, ``Perception.arm_points``) in the
        last ``steps`` scans taken after the arm moved, the current one included when it did,
        oldest first, (n, 3) (the arm's rule's view: a held arm sees what it saw, and the
        memory ages only as the arm moves)."""
        steps = int(steps)
        if steps <= 0:
            return np.zeros((0, 3))
        key = (len(self.scans), steps)
        if self._points is None or self._points[:2] != key:
            kept = self._moving[-steps:]
            points = [seen for i in kept
                      for seen in (self.scans[i].perception.hit_points, self.scans[i].perception.arm_points)]
            self._points = (*key, np.concatenate(points) if points else np.zeros((0, 3)))
        return self._points[2]
