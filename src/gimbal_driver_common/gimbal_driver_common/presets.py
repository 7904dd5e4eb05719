"""Driver-side presets stored in a YAML file, for devices without their own.

The file is rewritten atomically on every change so a preset survives a
driver restart or a power cut during the write.
"""

from __future__ import annotations

import contextlib
import math
import os
import tempfile
import threading
from dataclasses import dataclass, field

import yaml

from gimbal_driver_common.errors import InvalidRequest


def _fsync_directory(directory: str) -> None:
    """Make a rename in ``directory`` durable (no-op where directories cannot be opened)."""
    try:
        fd = os.open(directory, os.O_RDONLY | getattr(os, 'O_DIRECTORY', 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


class PresetError(InvalidRequest):
    """A preset request that cannot be served (unknown index, bad file, ...)."""


@dataclass
class StoredPreset:
    index: int
    name: str
    positions: dict[str, float] = field(default_factory=dict)


class PresetStore:
    """Presets by index; ``path`` empty keeps them in memory only."""

    MAX_INDEX = 65535

    def __init__(self, path: str = '') -> None:
        self.path = os.path.expanduser(path) if path else ''
        self._lock = threading.Lock()
        self._presets: dict[int, StoredPreset] = {}
        if self.path and os.path.exists(self.path):
            self._presets = self._load(self.path)

    @staticmethod
    def _load(path: str) -> dict[int, StoredPreset]:
        try:
            with open(path, encoding='utf-8') as stream:
                data = yaml.safe_load(stream) or {}
        except (OSError, yaml.YAMLError) as exc:
            raise PresetError(f'cannot read presets file {path}: {exc}') from exc
        presets: dict[int, StoredPreset] = {}
        try:
            for entry in data.get('presets', []):
                index = int(entry['index'])
                positions = {str(k): float(v) for k, v in entry['positions'].items()}
                presets[index] = StoredPreset(index, str(entry.get('name', '')), positions)
        except (AttributeError, KeyError, TypeError, ValueError) as exc:
            raise PresetError(f'presets file {path} is malformed: {exc}') from exc
        return presets

    def _save(self) -> None:
        if not self.path:
            return
        data = {
            'presets': [
                {'index': p.index, 'name': p.name, 'positions': dict(p.positions)}
                for p in sorted(self._presets.values(), key=lambda p: p.index)
            ]
        }
        directory = os.path.dirname(os.path.abspath(self.path))
        os.makedirs(directory, exist_ok=True)
        # Write a temporary file in the same directory, flush it to the disk, then rename it
        # over the old file: a reader (or the driver after a crash or power cut) sees either
        # the complete old set or the complete new one, never a half-written file.
        fd, tmp = tempfile.mkstemp(dir=directory, prefix='.presets-', suffix='.tmp')
        try:
            with os.fdopen(fd, 'w', encoding='utf-8') as stream:
                yaml.safe_dump(data, stream, sort_keys=False)
                stream.flush()
                os.fsync(stream.fileno())
            os.replace(tmp, self.path)
            _fsync_directory(directory)  # the rename itself survives a power cut
        except OSError as exc:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
            raise PresetError(f'cannot write presets file {self.path}: {exc}') from exc

    def set(self, index: int, name: str, positions: dict[str, float]) -> StoredPreset:
        if not 0 <= index <= self.MAX_INDEX:
            raise PresetError(f'preset index {index} out of range 0..{self.MAX_INDEX}')
        if not positions:
            raise PresetError('a preset needs at least one joint position')
        for joint, value in positions.items():
            if not math.isfinite(value):
                raise PresetError(f'preset position for {joint!r} is not finite: {value}')
        preset = StoredPreset(index, name, {k: float(v) for k, v in positions.items()})
        with self._lock:
            self._presets[index] = preset
            self._save()
        return preset

    def get(self, index: int) -> StoredPreset:
        with self._lock:
            try:
                return self._presets[index]
            except KeyError:
                known = sorted(self._presets)
                raise PresetError(f'no preset {index} (stored: {known or "none"})') from None

    def list(self) -> list[StoredPreset]:
        with self._lock:
            return sorted(self._presets.values(), key=lambda p: p.index)

    def clear(self, index: int | None = None) -> None:
        """Remove one preset, or every preset when ``index`` is None."""
        with self._lock:
            if index is None:
                self._presets.clear()
            elif self._presets.pop(index, None) is None:
                raise PresetError(f'no preset {index} to clear')
            self._save()

