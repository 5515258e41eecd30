"""colcon entry of the core library (pip uses the repository root's pyproject.toml)."""

from setuptools import find_packages, setup

package_name = "winder"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(include=["winder", "winder.*"]),
    package_data={"winder": ["py.typed", "ros/fastdds_profile.xml", "ros/fastdds_lan.xml"]},
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
    entry_points={"console_scripts": ["winder = winder.cli:main"]},
)
