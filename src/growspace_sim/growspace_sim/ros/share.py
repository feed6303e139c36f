"""A file a package installs under ``share/<package>/`` (its ``config/`` files)."""

from __future__ import annotations

import importlib.util
from pathlib import Path


def share_file(package: str, *parts: str) -> Path:
    """``share/<package>/<parts>`` of the sourced workspace, else the source tree's copy beside
    the Python package (not installed, or run outside a sourced workspace, where ament's index
    has no ``AMENT_PREFIX_PATH`` to search).

    Args:
        package: The ament package (also its Python package's name).
        parts: The path inside its share folder, e.g. ``'config', 'gantry.yaml'``.
    """
    try:
        from ament_index_python.packages import (
            get_package_share_directory, PackageNotFoundError)
    except ImportError:
        pass
    else:
        try:
            return Path(get_package_share_directory(package), *parts)
        except (PackageNotFoundError, OSError):  # OSError: AMENT_PREFIX_PATH unset
            pass
    spec = importlib.util.find_spec(package)
    if spec is None or not spec.submodule_search_locations:
        raise ModuleNotFoundError(f'no package {package!r} to find {"/".join(parts)} in')
    return Path(next(iter(spec.submodule_search_locations))).resolve().parent.joinpath(*parts)
