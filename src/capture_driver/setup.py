from glob import glob

from setuptools import find_packages, setup

package_name = 'capture_driver'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml', 'README.md']),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
        ('share/' + package_name + '/config', glob('config/*.yaml') + glob('config/*.xacro')),
        ('share/' + package_name + '/urdf', glob('urdf/*.urdf')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='Gimbal driver team',
    maintainer_email='gimbal-drivers@example.com',
    description='Capture Systems pan-tilt pedestal driver, simulator and protocol codec',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'capture_driver_node = capture_driver.node:main',
            'capture_sim = capture_driver.sim.cli:main',
        ],
        # the driver registry (gimbal_driver_common.registry): demo, soak, bench and tests
        'gimbal_driver_common.drivers': [
            'capture = capture_driver.registration:SPEC',
        ],
    },
)
