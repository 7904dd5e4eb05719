from glob import glob

from setuptools import find_packages, setup

PACKAGE = "ucamera_driver"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml", "README.md"]),
        (f"share/{PACKAGE}/launch", glob("launch/*.launch.py")),
        (f"share/{PACKAGE}/config", glob("config/*.yaml") + glob("config/*.xacro")),
        (f"share/{PACKAGE}/urdf", glob("urdf/*.urdf")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="Gimbal driver team",
    maintainer_email="gimbal-drivers@example.com",
    description="ROS 2 driver, simulator and UCSP codec for the Airelectronics U-Camera gimbal",
    license="Apache-2.0",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            f"ucamera_driver_node = {PACKAGE}.node:main",
            f"ucamera_sim = {PACKAGE}.sim.cli:main",
        ],
        # the driver registry (gimbal_driver_common.registry): demo, soak, bench and tests
        'gimbal_driver_common.drivers': [
            'ucamera = ucamera_driver.registration:SPEC',
        ],
    },
)
