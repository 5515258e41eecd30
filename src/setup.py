"""colcon entry of the core library (pip uses the repository root's pyproject.toml)."""

from setuptools import find_packages, setup

package_name = "winder"

setup(
    name=package_name,
    # the version: setup.cfg reads it from winder.__version__, as pyproject.toml does
    packages=find_packages(include=["winder", "winder.*"]),
    package_data={
        "winder": [
            "py.typed",
            "ros/fastdds_profile.xml",
            "ros/fastdds_lan.xml",
            "drives/twin.eds",
            "drives/examples/*.yaml",  # the example drives files (winder.drives.EXAMPLES)
        ]
    },
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="winder maintainers",
    maintainer_email="winder@users.noreply.github.com",
    description="winder core library",
    license="Apache-2.0",
    entry_points={
        "console_scripts": ["winder = winder.cli:main", "cia402_node = winder.ros.cia402_node:main"]
    },
)
