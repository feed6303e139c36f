"""Point the ROS 2 wheels' CMake exports at this venv's Python and numpy headers.

The exported targets of every message package in the ``ros-jazzy-*`` wheels name the include
paths of the image the wheels were built in (``/opt/python/cp311-cp311/include/python3.11`` and
that Python's ``numpy/_core/include``), so configuring a package that depends on them fails with
"Imported target ... includes non-existent path". This rewrites those two paths, only in the
``share/**/*.cmake`` files of the given venv, to the venv's own. Idempotent.

Usage: python scripts/fix_ros_wheel_cmake.py VENV   (run with that venv's python)
"""

from __future__ import annotations

from pathlib import Path
import re
import sys
import sysconfig

# /opt/python/cpXY-cpXY/include/pythonX.Y and .../site-packages/numpy/_core/include (or core/).
BUILD_IMAGE_PYTHON = re.compile(r'/opt/python/cp3\d+-cp3\d+/include/python3\.\d+t?')
BUILD_IMAGE_NUMPY = re.compile(
    r'/opt/python/cp3\d+-cp3\d+/lib/python3\.\d+t?/site-packages/numpy/_?core/include')


def rewrite(text: str, python_include: str, numpy_include: str) -> str:
    """``text`` with the build image's Python and numpy include paths replaced.

    Args:
        text: the content of a CMake file.
        python_include: this interpreter's include directory (holds Python.h).
        numpy_include: ``numpy.get_include()`` of this venv.

    Returns:
        The rewritten text (unchanged if it names neither path).
    """
    text = BUILD_IMAGE_NUMPY.sub(lambda _: numpy_include, text)
    return BUILD_IMAGE_PYTHON.sub(lambda _: python_include, text)


def fix_venv(venv: Path, python_include: str, numpy_include: str) -> list[Path]:
    """Rewrite every CMake file under ``venv/share`` that names the build image's paths.

    Returns:
        The files changed.
    """
    changed = []
    for path in sorted((venv / 'share').rglob('*.cmake')):
        text = path.read_text()
        if '/opt/python/' not in text:
            continue
        new = rewrite(text, python_include, numpy_include)
        if new != text:
            path.write_text(new)
            changed.append(path)
    return changed


def main(argv: list[str]) -> int:
    if len(argv) != 1 or not (Path(argv[0]) / 'share').is_dir():
        print(f'usage: python {Path(__file__).name} VENV (a venv with the ROS 2 wheels '
              f'installed, holding share/); got {argv!r}', file=sys.stderr)
        return 2
    import numpy

    python_include = sysconfig.get_paths()['include']
    if not (Path(python_include) / 'Python.h').is_file():
        print(f'warning: {python_include}/Python.h is missing; install the Python development '
              f'headers to build growspace_msgs.', file=sys.stderr)
    changed = fix_venv(Path(argv[0]), python_include, numpy.get_include())
    print(f'fix_ros_wheel_cmake: {len(changed)} CMake files now use {python_include} and '
          f'{numpy.get_include()}', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
