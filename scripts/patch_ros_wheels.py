"""Point the ROS wheels' CMake export files at this interpreter's include dirs.

The ros-jazzy-* wheels were built under /opt/python/cp311-cp311 and their
``*__rosidl_generator_pyExport.cmake`` files name that interpreter's Python and
numpy include directories. Building a message package that depends on them
(std_msgs, trajectory_msgs, ...) fails to configure until the paths name the
local interpreter's. Idempotent: a file already patched has nothing to replace.
"""

from __future__ import annotations

import re
import sys
import sysconfig
from pathlib import Path

import numpy

BUILD_PREFIX = re.compile(r'/opt/python/cp3\d+-cp3\d+')


def local_paths() -> dict[str, str]:
    return {
        'python_include': sysconfig.get_paths()['include'],
        'numpy_include': numpy.get_include(),
    }


def patch_text(text: str, paths: dict[str, str]) -> str:
    """Replace the wheel builder's include paths with ours."""

    def replace(match: re.Match[str]) -> str:
        path = match.group(0)
        if 'numpy' in path:
            return paths['numpy_include']
        return paths['python_include']

    return re.sub(r'/opt/python/cp3\d+-cp3\d+[^;"\s)]*', replace, text)


def main(prefix: str) -> int:
    paths = local_paths()
    changed = 0
    for cmake_file in Path(prefix, 'share').glob('*/cmake/*.cmake'):
        text = cmake_file.read_text(encoding='utf-8')
        if not BUILD_PREFIX.search(text):
            continue
        cmake_file.write_text(patch_text(text, paths), encoding='utf-8')
        changed += 1
    print(f'patch_ros_wheels: {changed} CMake export file(s) re-pointed to {paths}')
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1] if len(sys.argv) > 1 else sys.prefix))
