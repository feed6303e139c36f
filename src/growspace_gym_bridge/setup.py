"""ament_python package; also `pip install -e` on a machine without ROS (see README)."""

from setuptools import find_packages, setup

PACKAGE = 'growspace_gym_bridge'

setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', [f'resource/{PACKAGE}']),
        (f'share/{PACKAGE}', ['package.xml']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='GrowSpace maintainers',
    maintainer_email='growspace@example.com',
    description='Gymnasium bridge over the GrowSpace chamber topics.',
    license='Apache-2.0',
    python_requires='>=3.11',
)
