"""ament_python setup for the CANaerospace turret driver."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "canaero_turret_driver"

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
    maintainer_email="drivers@example.com",
    description="CANaerospace turret driver, simulator and protocol codec",
    license="Apache-2.0",
    tests_require=["pytest"],
    entry_points={
        "console_scripts": [
            f"canaero_turret_driver_node = {PACKAGE}.node:main",
            f"canaero_turret_sim = {PACKAGE}.sim.cli:main",
        ],
        # the driver registry (gimbal_driver_common.registry): demo, soak, bench and tests
        "gimbal_driver_common.drivers": [
            f"canaero_turret = {PACKAGE}.registration:SPEC",
        ],
    },
)
