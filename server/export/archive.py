"""An export's folder as one zip file (the API's answer)."""

from __future__ import annotations

import zipfile
from pathlib import Path


def zip_folder(folder: Path, into: Path, prefix: str) -> Path:
    """Every file under `folder` into the zip `into`, under `prefix/`; returns `into`."""
    with zipfile.ZipFile(into, "w", compression=zipfile.ZIP_DEFLATED) as z:
        for path in sorted(p for p in folder.rglob("*") if p.is_file()):
            z.write(path, f"{prefix}/{path.relative_to(folder).as_posix()}")
    return into
