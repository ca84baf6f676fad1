"""Where the shipped configuration lives, and how relative file parameters resolve."""

from __future__ import annotations

from pathlib import Path


def config_dir() -> Path:
    """msg_config/ of the source tree, or of the installed ament package."""
    source = Path(__file__).resolve().parents[3] / "msg_config"
    if source.is_dir():
        return source
    try:
        from ament_index_python.packages import get_package_share_directory
        return Path(get_package_share_directory("ato_nodes")) / "msg_config"
    except (ImportError, LookupError):
        return source


def resolve_file(given: str, bases: list[Path]) -> str:
    """An absolute path for a file parameter: as given if absolute, else the first of
    `bases` (the scenario's folder, the working directory, ...) that holds it, else
    msg_config/ (the nodes may run elsewhere, so the result is absolute)."""
    if not given or Path(given).is_absolute():
        return given
    for base in bases:
        candidate = base / given
        if candidate.exists():
            return str(candidate.resolve())
    return str((config_dir() / given).resolve())
