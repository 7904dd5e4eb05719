from setuptools import find_packages, setup

PACKAGE = 'gimbal_driver_common'

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
    entry_points={
        'console_scripts': [
            'gimbal_probe = gimbal_driver_common.probe_cli:main',
        ],
    },
    maintainer='Gimbal driver team',
    maintainer_email='drivers@example.com',
    description='Shared infrastructure of the gimbal driver suite',
    license='Apache-2.0',
    # colcon test runs pytest only for a package that lists it here (else unittest, which
    # finds none of these tests): colcon_core/task/python/test/pytest.py, match()
    tests_require=['pytest'],
)
