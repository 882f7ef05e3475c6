"""Saved policies: one zip holds the PPO model, its observation normalisation and metadata.

The file is stable-baselines3's own zip with two more entries, ``rayreach/meta.json`` and
``rayreach/normalization.npz``, so evaluation always sees the statistics training saw, frozen.
Checkpoints use the same format and also carry the optimiser, the reward normalisation and
the curricula, so training resumes where it stopped.
"""

from __future__ import annotations

import io
import json
import os
import tempfile
import zipfile
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import numpy as np

META_ENTRY = "rayreach/meta.json"
NORM_ENTRY = "rayreach/normalization.npz"
FORMAT = 1


class CheckpointError(ValueError):
    """A model or checkpoint file that cannot be used; the message says why."""


@dataclass
class Normalization:
    """Frozen observation normalisation: (obs - mean) / sqrt(var + eps), clipped."""

    mean: np.ndarray
    var: np.ndarray
    clip: float
    epsilon: float

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        out = (np.asarray(obs, dtype=np.float64) - self.mean) / np.sqrt(self.var + self.epsilon)
        return np.clip(out, -self.clip, self.clip).astype(np.float32)

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray] | None) -> "Normalization | None":
        """The frozen observation normalisation of a bundle's arrays; None if it has none."""
        if arrays is None or not bool(arrays["norm_obs"]):
            return None
        return cls(arrays["obs_mean"], arrays["obs_var"], float(arrays["clip_obs"]), float(arrays["epsilon"]))


def normalization_arrays(vecnorm: Any) -> dict[str, np.ndarray]:
    """Everything a VecNormalize needs to continue, as arrays."""
    return {
        "obs_mean": vecnorm.obs_rms.mean,
        "obs_var": vecnorm.obs_rms.var,
        "obs_count": np.array(vecnorm.obs_rms.count),
        "ret_mean": np.array(vecnorm.ret_rms.mean),
        "ret_var": np.array(vecnorm.ret_rms.var),
        "ret_count": np.array(vecnorm.ret_rms.count),
        "clip_obs": np.array(vecnorm.clip_obs),
        "clip_reward": np.array(vecnorm.clip_reward),
        "epsilon": np.array(vecnorm.epsilon),
        "norm_obs": np.array(vecnorm.norm_obs),
        "norm_reward": np.array(vecnorm.norm_reward),
    }


def restore_normalization(vecnorm: Any, arrays: dict[str, np.ndarray]) -> None:
    vecnorm.obs_rms.mean = arrays["obs_mean"].copy()
    vecnorm.obs_rms.var = arrays["obs_var"].copy()
    vecnorm.obs_rms.count = float(arrays["obs_count"])
    vecnorm.ret_rms.mean = float(arrays["ret_mean"])
    vecnorm.ret_rms.var = float(arrays["ret_var"])
    vecnorm.ret_rms.count = float(arrays["ret_count"])


def save_bundle(model: Any, path: str | Path, meta: dict[str, Any], vecnorm: Any | dict[str, np.ndarray] | None) -> Path:
    """Write model + metadata + normalisation atomically (a crash never leaves half a file).
    ``vecnorm``: a VecNormalize, or the arrays ``read_bundle_meta`` returned for one."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with _written_atomically(path) as tmp:
        model.save(tmp)
        with zipfile.ZipFile(tmp, "a") as archive:
            _write_meta(archive, meta)
            if vecnorm is not None:
                buffer = io.BytesIO()
                np.savez(buffer, **(vecnorm if isinstance(vecnorm, dict) else normalization_arrays(vecnorm)))
                archive.writestr(NORM_ENTRY, buffer.getvalue())
    return path


def copy_bundle(source: str | Path, path: str | Path, meta: dict[str, Any]) -> Path:
    """Copy a bundle with new metadata, atomically as ``save_bundle`` writes one."""
    path = Path(path)
    with _written_atomically(path) as tmp:
        with zipfile.ZipFile(source) as old, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as new:
            for item in old.infolist():
                if item.filename != META_ENTRY:
                    new.writestr(item, old.read(item.filename))
            _write_meta(new, meta)
    return path


@contextmanager
def _written_atomically(path: Path) -> Iterator[str]:
    """A temporary file beside ``path`` to write; it replaces ``path`` only if the writing
    ended without an exception, and is removed either way."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".", suffix=".part.zip")
    os.close(fd)
    try:
        yield tmp
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def _write_meta(archive: zipfile.ZipFile, meta: dict[str, Any]) -> None:
    archive.writestr(META_ENTRY, json.dumps({"format": FORMAT, **meta}, indent=2, default=_json_default))


def _json_default(value: Any) -> Any:
    if isinstance(value, (np.integer, np.floating)):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return str(value)


def read_bundle_meta(path: str | Path) -> tuple[dict[str, Any], dict[str, np.ndarray] | None]:
    """Metadata and normalisation arrays of a bundle; a clear error for anything else."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"no model file at {path}")
    try:
        with zipfile.ZipFile(path) as archive:
            names = set(archive.namelist())
            if META_ENTRY not in names or "policy.pth" not in names:
                raise CheckpointError(
                    f"{path} is not a rayreach model or checkpoint (missing {META_ENTRY} or policy.pth)"
                )
            meta = json.loads(archive.read(META_ENTRY))
            norm = None
            if NORM_ENTRY in names:
                with np.load(io.BytesIO(archive.read(NORM_ENTRY))) as data:
                    norm = {k: data[k] for k in data.files}
    except (zipfile.BadZipFile, json.JSONDecodeError, OSError, ValueError, KeyError) as exc:
        if isinstance(exc, CheckpointError):
            raise
        raise CheckpointError(f"{path} is corrupt or truncated: {exc}") from exc
    if meta.get("format") != FORMAT:
        raise CheckpointError(f"{path} has format {meta.get('format')!r}; this rayreach reads format {FORMAT}")
    return meta, norm
