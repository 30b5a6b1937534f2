"""Output paths checked before any job runs (issue 18): creatable, writable, not under a file.

The checks leave nothing behind: a directory that does not exist yet is probed by creating and
removing a temporary directory in its nearest existing ancestor (so /proc, read-only mounts and
paths under a regular file are refused even for root, where os.access says yes).
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

from impactval.errors import ImpactvalError


def _text(path) -> str:
    if not isinstance(path, (str, os.PathLike)):
        raise TypeError
    return os.fspath(path)


def _refuse(option: str, path, why: str, fix: str) -> ImpactvalError:
    return ImpactvalError(f"{option} {str(path)!r} {why}; {fix}.")


def _existing_ancestor(path: Path, option: str) -> Path:
    """The nearest ancestor of `path` that exists; refused when it is not a directory."""
    for parent in path.absolute().parents:
        if parent.exists():
            if not parent.is_dir():
                raise _refuse(option, path, f"is under {str(parent)!r}, which is a file, not a directory",
                              "choose a path outside it")
            return parent
    return Path(path.anchor or "/")  # pragma: no cover - the root always exists


def _probe_dir(directory: Path, option: str, shown) -> None:
    """Create and remove a temporary directory in `directory`."""
    try:
        probe = tempfile.mkdtemp(prefix=".impactval-probe-", dir=directory)
    except OSError as err:
        raise _refuse(option, shown, f"cannot be created or written ({err.strerror or err})",
                      "choose a writable location") from None
    os.rmdir(probe)


def _check_text(path, option: str) -> Path:
    try:
        text = _text(path)
    except TypeError:
        raise ImpactvalError(f"{option} must be a path, got {path!r}.") from None
    if not text.strip():
        raise ImpactvalError(f"{option} must be a path, got an empty string.")
    if "\x00" in text:
        raise ImpactvalError(f"{option} {text!r} contains a NUL character; give a plain path.")
    return Path(text)


def check_output_dir(path, option_name: str = "--out") -> Path:
    """Check that `path` is (or can be made) a writable directory; return it as a Path.

    Raises ImpactvalError naming `option_name` when the path is empty, an existing file, under a file,
    or not writable. Nothing is created.
    """
    p = _check_text(path, option_name)
    try:
        if p.exists():
            if not p.is_dir():
                raise _refuse(option_name, p, "is an existing file, not a directory", "give a directory path")
            _probe_dir(p, option_name, p)
        else:
            _probe_dir(_existing_ancestor(p, option_name), option_name, p)
    except OSError as err:      # e.g. a name too long, a path through an unreadable directory
        raise _refuse(option_name, p, f"cannot be used ({err.strerror or err})", "choose another path") from None
    return p


def check_output_file(path, option_name: str) -> Path:
    """Check that `path` is a file that can be written (created, or appended to); return it as a Path.

    Refused: an empty path, an existing directory, a path under a file, a directory that cannot be
    created or written, a file that cannot be opened for writing. Nothing is created or truncated.
    """
    p = _check_text(path, option_name)
    try:
        if p.is_dir():
            raise _refuse(option_name, p, "is a directory", "give a file path (e.g. curve.csv)")
        if p.exists():
            try:
                with p.open("a"):
                    pass
            except OSError as err:
                raise _refuse(option_name, p, f"cannot be written ({err.strerror or err})",
                              "choose a writable file") from None
        elif p.parent.exists():
            if not p.parent.is_dir():
                raise _refuse(option_name, p, f"is under {str(p.parent)!r}, which is a file, not a directory",
                              "choose a path outside it")
            _probe_dir(p.parent, option_name, p)
        else:
            _probe_dir(_existing_ancestor(p, option_name), option_name, p)
    except OSError as err:
        raise _refuse(option_name, p, f"cannot be used ({err.strerror or err})", "choose another path") from None
    return p


def write_guard(option_name: str, path):
    """Context manager: an OSError while writing `path` becomes an ImpactvalError naming the option
    (the disk filled up, the path was removed meanwhile)."""
    return _WriteGuard(option_name, path)


class _WriteGuard:
    def __init__(self, option_name: str, path) -> None:
        self.option_name, self.path = option_name, path

    def __enter__(self):
        return self

    def __exit__(self, kind, err, tb) -> bool:
        if err is not None and isinstance(err, OSError):
            raise _refuse(self.option_name, self.path, f"could not be written ({err.strerror or err})",
                          "check the disk space and permissions") from None
        return False
