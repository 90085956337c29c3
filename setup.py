"""ament_python package ``hiros``: every Python package of the suite and its executables."""

from pathlib import Path

from setuptools import find_packages, setup

PACKAGE = "hiros"
NODES = {
    "azure_bridge": "hiros_azure_bridge.node:main",
    "generic_bridge": "hiros_azure_bridge.node:generic_main",
    "calib": "hiros_calib.node:main",
    "tracker": "hiros_tracker.node:main",
    "merger": "hiros_merger.node:main",
    "optimizer": "hiros_optimizer.node:main",
    "filter": "hiros_filter.node:main",
    "pipeline": "hiros_pipeline.node:main",
    "visualizer": "hiros_visualizer.node:main",
}

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*", "build", "install"]),
    package_data={"hiros_data": ["**/*"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", [str(p) for p in sorted(Path("config").glob("*.yaml"))]),
        (f"share/{PACKAGE}/config/rviz", ["config/rviz/hiros.rviz"]),
        (f"share/{PACKAGE}/config/foxglove", ["config/foxglove/hiros_layout.json"]),
        (f"share/{PACKAGE}/launch", [str(p) for p in sorted(Path("launch").glob("*.py"))]),
        (f"share/{PACKAGE}/rviz", [str(p) for p in sorted(Path("rviz").glob("*.rviz"))]),
    ],
    install_requires=["setuptools"],
    zip_safe=False,
    maintainer="hiros developers",
    maintainer_email="hiros@example.com",
    description="Markerless multi-camera motion capture for ROS 2",
    license="MIT",
    entry_points={
        "console_scripts": [
            "hiros = hiros_cli.main:main",
            *(f"{name} = {target}" for name, target in NODES.items()),
        ],
    },
)
