"""The data files a running service was started with, and which have changed since.

The service reads srlab's data files (``core/data``: sensors, behaviours, worlds, networks,
conditions, trainers) once, at its start and in the runs' process, and keeps what it read;
a file edited under it is not picked up until it restarts. `DataWatch` makes that visible
instead of silent: the data's version (a digest of every file as the service read them),
and which files differ now (edited, added or removed), for `GET /api/health`, the pages'
banner and one warning a file in the log.
"""

from __future__ import annotations

import hashlib
import logging
import threading
from pathlib import Path

from core.brain.catalog import data_dir

log = logging.getLogger("srlab.data")

PATTERN = "*.toml"
"""What counts as a data file."""


def _digest(path: Path) -> str:
    try:
        return hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError:
        return "unreadable"


class DataWatch:
    """The data files under `root` as they were when made, and the ones changed since.

    Cheap to ask often: a file is read again only when its size or modification time
    changed; one whose content is back as it was (an edit undone) is not reported.
    """

    def __init__(self, root: Path | None = None) -> None:
        self.root = root or data_dir()
        self._lock = threading.Lock()
        self._stats: dict[Path, tuple[int, int]] = {}
        self._now: dict[Path, str] = {}
        for path in self._files():
            self._stats[path] = self._stat(path)
            self._now[path] = _digest(path)
        self._started = dict(self._now)
        self._warned: set[Path] = set()
        joined = "\n".join(f"{self._name(p)} {d}" for p, d in sorted(self._started.items()))
        self.version = hashlib.sha256(joined.encode()).hexdigest()[:12]
        """The data's version as the service read it: a digest of every file's content."""

    def _files(self) -> list[Path]:
        return sorted(p for p in self.root.rglob(PATTERN) if p.is_file())

    @staticmethod
    def _stat(path: Path) -> tuple[int, int]:
        try:
            st = path.stat()
        except OSError:
            return (-1, -1)
        return st.st_mtime_ns, st.st_size

    def _name(self, path: Path) -> str:
        return path.relative_to(self.root).as_posix()

    def changed(self) -> list[str]:
        """The files (relative to `root`) that differ from the service's start, sorted.

        Each is logged once, as a warning, when first seen changed.
        """
        with self._lock:
            files = set(self._files())
            for path in files | set(self._now):
                stat = self._stat(path) if path in files else (-1, -1)
                if self._stats.get(path) != stat:
                    self._stats[path] = stat
                    self._now[path] = _digest(path) if path in files else "removed"
            out = sorted(p for p in self._now if self._now[p] != self._started.get(p, "added"))
            for path in out:
                if path not in self._warned:
                    self._warned.add(path)
                    log.warning(
                        "data file %s changed since the service started: it keeps using "
                        "the data as it was until it is restarted",
                        path,
                    )
            return [self._name(p) for p in out]
