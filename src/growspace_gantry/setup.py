"""ament_python package; also `pip install -e` on a machine without ROS (see README)."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = 'growspace_gantry'

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
    description='LED-gantry driver (GRBL 1.1 over serial) for the GrowSpace chamber topics.',
    license='Apache-2.0',
    python_requires='>=3.11',
    entry_points={
        'console_scripts': [
            'gantry_node = growspace_gantry.main:main',
            'growspace-gantry-gcode = growspace_gantry.gcode:main',
        ],
    },
)
