"""What the command-line tests share: a clean usage error, and what a plot file must be."""

from __future__ import annotations

from pathlib import Path

import matplotlib.image
import pytest

from server.cli import main

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def exits_2(argv: list[str], capsys: pytest.CaptureFixture[str]) -> str:
    """Run the CLI expecting exit code 2 and no traceback; return stderr."""
    with pytest.raises(SystemExit) as e:
        main(argv)
    assert e.value.code == 2
    captured = capsys.readouterr()
    assert "Traceback" not in captured.err
    assert "Traceback" not in captured.out
    return captured.err


def assert_png(path: Path, at_least: int = 100) -> None:
    """`path` is a PNG image at least `at_least` pixels high and wide."""
    assert path.read_bytes()[:8] == PNG_SIGNATURE
    height, width = matplotlib.image.imread(path).shape[:2]
    assert height > at_least
    assert width > at_least
