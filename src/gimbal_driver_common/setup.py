from glob import glob

from setuptools import find_packages, setup

PACKAGE = 'gimbal_driver_common'

setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', [f'resource/{PACKAGE}']),
        (f'share/{PACKAGE}', ['package.xml']),
        (f'share/{PACKAGE}/urdf', glob('urdf/*.urdf')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='Gimbal driver team',
    maintainer_email='drivers@example.com',
    description='Shared infrastructure of the gimbal driver suite',
    license='Apache-2.0',
    entry_points={
        'console_scripts': [
            # Reference driver and simulator used to test the shared base node.
            'virtual_gimbal_sim = gimbal_driver_common.virtual_gimbal:sim_main',
            'virtual_gimbal_node = gimbal_driver_common.virtual_gimbal:node_main',
        ],
        # the driver registry (gimbal_driver_common.registry): demo, soak, bench and tests
        'gimbal_driver_common.drivers': [
            'virtual_gimbal = gimbal_driver_common.registration:SPEC',
        ],
    },
)
