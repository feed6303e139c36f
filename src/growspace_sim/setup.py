"""ament_python package; also `pip install -e` on a machine without ROS (see README)."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = 'growspace_sim'

setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', [f'resource/{PACKAGE}']),
        (f'share/{PACKAGE}', ['package.xml']),
        (f'share/{PACKAGE}/config', glob('config/*.yaml') + glob('config/*.xml')),
        (f'share/{PACKAGE}/launch', glob('launch/*.launch.py')),
        (f'share/{PACKAGE}/config/foxglove', glob('config/foxglove/*.json')),
    ],
    # Runtime libraries come from rosdep (package.xml) or requirements.txt; listing them here
    # would make the generated console scripts refuse to start beside apt-installed numpy/cv2.
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='GrowSpace maintainers',
    maintainer_email='growspace@example.com',
    description='GrowSpace plant-growth chamber simulation, ROS 2 node and Gymnasium envs.',
    license='Apache-2.0',
    python_requires='>=3.11',
    entry_points={
        'console_scripts': [
            'growspace-eval = growspace_sim.tools.evaluate:main',
            'growspace-train = growspace_sim.learn:train_main',
            'growspace-compare = growspace_sim.learn.evaluate_policies:main',
            'growspace-sweep = growspace_sim.sweep:main',
            'growspace-bench = growspace_sim.tools.bench:main',
            'growspace-demo = growspace_sim.tools.demo:main',
            'growspace-record = growspace_sim.tools.record:main',
            'growspace-replay = growspace_sim.replay:main',
            'growspace-rig = growspace_sim.rig.cli:main',
            'sim_node = growspace_sim.node.main:main',
            'teleop = growspace_sim.tools.teleop:main',
            'view_node = growspace_sim.node.view_node:main',
        ],
    },
)
