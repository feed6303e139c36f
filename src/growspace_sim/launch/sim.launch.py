"""Launch one chamber: ``ros2 launch growspace_sim sim.launch.py namespace:=chamber1``.

Arguments: ``namespace`` (default ``growspace``), ``params_file`` (default the installed
``config/growspace.yaml``), ``view`` (default ``false``; ``true`` also starts ``view_node``,
which publishes ``plant/markers`` and ``camera/image_view`` in the same namespace) and
``foxglove_port`` (default ``0``: with ``view:=true``, a port starts its Foxglove WebSocket
server on 127.0.0.1). Several chambers run side by side in different namespaces.
"""

from __future__ import annotations

import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue


def generate_launch_description() -> LaunchDescription:
    default_params = os.path.join(get_package_share_directory('growspace_sim'), 'config',
                                  'growspace.yaml')
    return LaunchDescription([
        DeclareLaunchArgument('namespace', default_value='growspace',
                              description='ROS namespace of the chamber'),
        DeclareLaunchArgument('params_file', default_value=default_params,
                              description='ROS params file of sim_node'),
        DeclareLaunchArgument('view', default_value='false',
                              description='also start view_node (markers and view image)'),
        DeclareLaunchArgument('foxglove_port', default_value='0',
                              description="view_node's Foxglove WebSocket port; 0 = none"),
        Node(package='growspace_sim', executable='sim_node', name='growspace_sim',
             namespace=LaunchConfiguration('namespace'),
             parameters=[LaunchConfiguration('params_file')], output='screen',
             emulate_tty=True),
        Node(package='growspace_sim', executable='view_node', name='growspace_view',
             namespace=LaunchConfiguration('namespace'),
             parameters=[{'foxglove_port': ParameterValue(LaunchConfiguration('foxglove_port'),
                                                          value_type=int)}],
             condition=IfCondition(LaunchConfiguration('view')), output='screen',
             emulate_tty=True),
    ])
