from setuptools import find_packages, setup

PACKAGE = 'gimbal_driver_testing'

setup(
    name=PACKAGE,
    version='0.1.0',
    packages=find_packages(exclude=['test']),
    data_files=[
        ('share/ament_index/resource_index/packages', [f'resource/{PACKAGE}']),
        (f'share/{PACKAGE}', ['package.xml', 'README.md']),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='Gimbal driver team',
    maintainer_email='drivers@example.com',
    description='Test support of the gimbal driver suite (conformance suites, ROS test client)',
    license='Apache-2.0',
    # colcon test runs pytest only for a package that lists it here (else unittest, which
    # finds none of these tests): colcon_core/task/python/test/pytest.py, match()
    tests_require=['pytest'],
)
