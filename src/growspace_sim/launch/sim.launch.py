"""Launch one chamber: ``ros2 launch growspace_sim sim.launch.py namespace:=chamber1``.

Arguments: ``namespace`` (default ``growspace``) and ``params_file`` (default the installed
``config/growspace.yaml``). Several chambers run side by side in different namespaces.
"""

from __future__ import annotations

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description() -> LaunchDescription:
    default_params = os.path.join(get_package_share_directory('growspace_sim'), 'config',
                                  'growspace.yaml')
    return LaunchDescription([
        DeclareLaunchArgument('namespace', default_value='growspace',
                              description='ROS namespace of the chamber'),
        DeclareLaunchArgument('params_file', default_value=default_params,
                              description='ROS params file of sim_node'),
        Node(package='growspace_sim', executable='sim_node', name='growspace_sim',
             namespace=LaunchConfiguration('namespace'),
             parameters=[LaunchConfiguration('params_file')], output='screen',
             emulate_tty=True),
    ])
