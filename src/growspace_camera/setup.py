"""ament_python package; also `pip install -e` on a machine without ROS (see README)."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = 'growspace_camera'

setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', [f'resource/{PACKAGE}']),
        (f'share/{PACKAGE}', ['package.xml']),
        (f'share/{PACKAGE}/config', glob('config/*.yaml')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='GrowSpace maintainers',
    maintainer_email='growspace@example.com',
    description='Camera for the GrowSpace chamber: photos to observation, plant state and reward.',
    license='Apache-2.0',
    python_requires='>=3.11',
    entry_points={
        'console_scripts': [
            'camera_node = growspace_camera.main:main',
            'growspace-camera = growspace_camera.cli:main',
        ],
    },
)
