"""A real ROS 2 workspace: manifests parse, colcon sees the packages, interfaces parse."""

from __future__ import annotations

from pathlib import Path
import shutil
import subprocess
import sys

from catkin_pkg.package import parse_package
import pytest
from rosbags.typesys import get_types_from_msg

from growspace_sim.ros import types

ROOT = Path(__file__).resolve().parents[2]
EXPECTED_PACKAGES = {
    'growspace_msgs': 'ros.ament_cmake',
    'growspace_sim': 'ros.ament_python',
    'growspace_gym_bridge': 'ros.ament_python',
    'growspace_gantry': 'ros.ament_python',
    'growspace_camera': 'ros.ament_python',
}
MANIFESTS = sorted((ROOT / 'src').glob('*/package.xml'))


def colcon() -> str:
    exe = Path(sys.executable).with_name('colcon')
    found = str(exe) if exe.exists() else shutil.which('colcon')
    if not found:
        pytest.skip('colcon is not installed')
    return found


@pytest.mark.parametrize('manifest', MANIFESTS, ids=[m.parent.name for m in MANIFESTS])
def test_package_xml_is_format_3(manifest: Path) -> None:
    package = parse_package(str(manifest))
    assert package.package_format == 3
    assert package.name == manifest.parent.name
    assert package.licenses and package.maintainers
    package.validate()


def test_msgs_package_declares_rosidl() -> None:
    package = parse_package(str(ROOT / 'src' / 'growspace_msgs' / 'package.xml'))
    assert 'rosidl_interface_packages' in [g.name for g in package.member_of_groups]
    assert {'ament_cmake', 'rosidl_default_generators'} <= {
        d.name for d in package.buildtool_depends}
    assert {'std_msgs', 'builtin_interfaces'} <= {d.name for d in package.build_depends}
    assert {'std_msgs', 'builtin_interfaces', 'rosidl_default_runtime'} <= {
        d.name for d in package.exec_depends}
    cmake = (ROOT / 'src' / 'growspace_msgs' / 'CMakeLists.txt').read_text()
    interfaces = sorted(p.relative_to(ROOT / 'src' / 'growspace_msgs').as_posix() for p in
                        (ROOT / 'src' / 'growspace_msgs').glob('*/*.*') if p.suffix in
                        ('.msg', '.srv'))
    for interface in interfaces:
        assert f'"{interface}"' in cmake, f'{interface} is not in rosidl_generate_interfaces'
    assert 'DEPENDENCIES builtin_interfaces std_msgs' in cmake


def test_colcon_finds_all_packages() -> None:
    # --log-base /dev/null: listing must not leave a log/ folder in the workspace.
    out = subprocess.run([colcon(), '--log-base', '/dev/null', 'list', '--base-paths', 'src'],
                         cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    found = {}
    for line in out.stdout.splitlines():
        name, _path, kind = line.split('\t')
        found[name] = kind.strip('()')
    assert found == EXPECTED_PACKAGES


def test_every_interface_parses_with_rosbags() -> None:
    texts = types.interface_texts(ROOT / 'src' / 'growspace_msgs')
    assert set(texts) == {
        'growspace_msgs/msg/CameraMeasurement', 'growspace_msgs/msg/LightCommand',
        'growspace_msgs/msg/PlantState', 'growspace_msgs/msg/ResetRequest',
        'growspace_msgs/msg/StepResult', 'growspace_msgs/srv/Capture_Request',
        'growspace_msgs/srv/Capture_Response', 'growspace_msgs/srv/Reset_Request',
        'growspace_msgs/srv/Reset_Response'}
    for name, text in texts.items():
        short = name.rsplit('/', 1)[1]
        parsed = get_types_from_msg(text, f'growspace_msgs/msg/{short}')
        assert parsed[f'growspace_msgs/msg/{short}'][1], f'{name} has no fields'


@pytest.mark.slow
def test_the_loopback_rule_applies_outside_a_sourced_workspace() -> None:
    # The tests' conftest confines ROS to loopback first thing; with no AMENT_PREFIX_PATH
    # (a plain `PYTHONPATH=src/growspace_sim pytest`) ament's index cannot be searched.
    import os

    env = {k: v for k, v in os.environ.items()
           if k not in ('AMENT_PREFIX_PATH', 'FASTRTPS_DEFAULT_PROFILES_FILE',
                        'ROS_AUTOMATIC_DISCOVERY_RANGE')}
    env['PYTHONPATH'] = str(ROOT / 'src' / 'growspace_sim')
    code = ('from growspace_sim.ros import loopback\n'
            'env = loopback.confine({})\n'
            'import pathlib; print(env[loopback.RANGE_VAR], '
            'pathlib.Path(env[loopback.PROFILE_VAR]).is_file())\n')
    out = subprocess.run([sys.executable, '-c', code], env=env, capture_output=True, text=True,
                         timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ['LOCALHOST', 'True']
