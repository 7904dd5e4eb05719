from glob import glob

from setuptools import find_packages, setup

package_name = 'virtual_gimbal_driver'

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
    description='Reference driver: an invented pan-tilt device on the shared core',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'virtual_gimbal_driver_node = virtual_gimbal_driver.node:main',
            'virtual_gimbal_sim = virtual_gimbal_driver.sim:main',
        ],
        # the driver registry (gimbal_driver_common.registry): demo, soak, bench and tests
        'gimbal_driver_common.drivers': [
            'virtual_gimbal = virtual_gimbal_driver.registration:SPEC',
        ],
    },
)
