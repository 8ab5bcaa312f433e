"""Output files of the commands: checked before any work is done, and written whole or not at all."""

from __future__ import annotations

import os
from pathlib import Path

from mrguide.errors import InputError


class OutputPathError(InputError):
    """An output location that cannot be written: a file in the way, a directory, no write permission."""


def check_output_dir(path: str | Path, option: str) -> Path:
    """Refuse directory `path` (given by `option`, e.g. "--out") unless it exists or can be created, and can be
    written into. Creates nothing."""
    path = Path(path)
    problem = _directory_problem(path)
    if problem:
        raise OutputPathError(f"{option} {path}: {problem}")
    return path


def check_output_file(path: str | Path, option: str) -> Path:
    """Refuse file `path` (given by `option`) unless a regular file can be created or replaced there. Creates
    nothing."""
    path = Path(path)
    problem = (
        "exists and is not a regular file" if path.exists() and not path.is_file() else _directory_problem(path.parent)
    )
    if problem:
        raise OutputPathError(f"{option} {path}: {problem}")
    return path


def _directory_problem(path: Path) -> str | None:
    """Why directory `path` cannot be created or written into, or None (judged by its nearest existing ancestor)."""
    ancestor = path
    while not ancestor.exists() and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        return f"{ancestor} is not a directory"
    if not os.access(ancestor, os.W_OK | os.X_OK):
        return f"cannot write in {ancestor}"
    return None


def write_files_atomically(contents: dict[Path, bytes]) -> None:
    """Write every file of `contents` whole, or none: temporary files beside them first, then renames.

    An OSError (a full disk) leaves the files that were there before untouched and no temporary behind."""
    temporaries: list[tuple[Path, Path]] = []
    try:
        for path, data in contents.items():
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
            temporaries.append((tmp, path))
            with tmp.open("wb") as fh:
                fh.write(data)
                fh.flush()
                os.fsync(fh.fileno())
        for tmp, path in temporaries:
            tmp.replace(path)
    finally:
        for tmp, _ in temporaries:
            tmp.unlink(missing_ok=True)
