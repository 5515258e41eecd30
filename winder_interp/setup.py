from glob import glob

from setuptools import find_packages, setup

package_name = "winder_interp"

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    # the package beside this file, said so: pip's editable install then puts this
    # directory on sys.path (a .pth line, as for the core's src/) instead of an import
    # hook, which a directory named as the package (this one, from the repository's
    # root) shadows, and of which setuptools warns at every install
    package_dir={"": "."},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/launch", glob("launch/*.launch.py")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="winder maintainers",
    maintainer_email="winder@users.noreply.github.com",
    description="Trajectory node: winding job to minimum-deviation step commands",
    license="Apache-2.0",
    entry_points={"console_scripts": ["interp_node = winder_interp:main"]},
)
