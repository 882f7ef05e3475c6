"""Three disjoint ranges of random-world seeds: train on one, tune on another, quote the third.

A figure measured on worlds somebody tuned on says how well the tuning fits those worlds,
not how the planner does on the next one. Training draws its worlds below 1,000,000;
every threshold, radius and clearance of the acting layers is chosen on the validation
range; the figures the docs quote come from the test range, which nobody tunes on.
"""

from __future__ import annotations

from dataclasses import dataclass

SEED_LIMIT = 2**32
"""NumPy seeds are below this."""


@dataclass(frozen=True)
class SeedSplit:
    name: str
    start: int
    stop: int
    """First seed past the range."""

    def seed(self, index: int) -> int:
        """The seed of world ``index`` (0, 1, ...) of this split."""
        if not 0 <= index < self.stop - self.start:
            raise ValueError(f"world {index} lies outside the {self.name} split ({self.stop - self.start} worlds)")
        return self.start + index

    def __contains__(self, seed: int) -> bool:
        return self.start <= seed < self.stop


SPLITS = {s.name: s for s in (SeedSplit("train", 0, 1_000_000), SeedSplit("validation", 1_000_000, 9_000_000),
                              SeedSplit("test", 9_000_000, SEED_LIMIT))}
"""``train``: training's worlds; ``validation``: tuning; ``test``: quoted, never tuned on."""

EVALUATION_SPLITS = ("validation", "test")
"""The splits ``rollout`` and ``evaluate`` draw worlds from."""


def get_split(name: str) -> SeedSplit:
    """The split called ``name``; the error names the valid ones."""
    try:
        return SPLITS[name]
    except KeyError:
        raise ValueError(f"unknown seed split '{name}'; valid: {', '.join(SPLITS)}") from None


def split_of(seed: int) -> str:
    """The name of the split ``seed`` lies in."""
    for split in SPLITS.values():
        if seed in split:
            return split.name
    raise ValueError(f"seed {seed} lies outside every split (0 to {SEED_LIMIT - 1})")
