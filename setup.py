"""ament_python package: `colcon build` on a ROS install, or `pip install -e .[test]` here."""

import os
import runpy
from glob import glob

from setuptools import find_packages, setup

package_name = "exo_ilc_ros"
HERE = os.path.dirname(os.path.abspath(__file__))
REGISTRY = runpy.run_path(os.path.join(HERE, package_name, "nodes", "registry.py"))
"""The node registry (plain data: read without importing the package)."""

DOCS_DEPENDENCIES = ["sphinx>=8", "myst-parser>=4", "furo>=2024.8", "sphinx-argparse>=0.5"]
"""`make docs` (and so `make test`): the documentation site. Tooling, not a runtime dependency."""

ROS_DEPENDENCIES = [
    "ros-jazzy-rclpy[fastrtps]",
    "ros-jazzy-sensor-msgs",
    "ros-jazzy-std-msgs",
    "ros-jazzy-trajectory-msgs",
    "ros-jazzy-diagnostic-msgs",
    "ros-jazzy-rosgraph-msgs",
    "ros-jazzy-geometry-msgs",
    "ros-jazzy-std-srvs",
    "ros-jazzy-rcl-interfaces",
    "ros-jazzy-ament-index-python",
]

setup(
    name=package_name,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*", "bench"]),
    package_data={package_name: ["py.typed"]},  # PEP 561: the package ships its type hints
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + package_name]),
        ("share/" + package_name, ["package.xml"]),
        ("share/" + package_name + "/config", glob("config/*.yaml")),
        ("share/" + package_name + "/config/layouts", glob("config/layouts/*")),
        ("share/" + package_name + "/config/scenarios", glob("config/scenarios/*.yaml")),
        ("share/" + package_name + "/config/arms", glob("config/arms/*.yaml")),
        ("share/" + package_name + "/config/exercises", glob("config/exercises/*.yaml")),
        ("share/" + package_name + "/config/ros2_control", glob("config/ros2_control/*.yaml")),
        ("share/" + package_name + "/urdf", glob("urdf/*.urdf") + glob("urdf/LICENSE.*")),
        ("share/" + package_name + "/launch", glob("launch/*.py")),
    ],
    python_requires=">=3.11,<3.12",
    install_requires=[
        "setuptools",
        *ROS_DEPENDENCIES,
        "numpy>=1.26",
        "numba>=0.60",
        "scipy>=1.11",
        "pyyaml>=6",
        "tqdm>=4.66",
        "matplotlib>=3.8",
        "rosbags>=0.11.9,<0.12",  # tested: 0.11.9 (typestore, sqlite3 bags); MCAP is mcap's
        "mcap>=1.6,<2",  # tested: 1.6.0 (Writer with chunk, data and summary CRCs)
        "mcap-ros2-support>=0.5",
        "optuna>=4",
        "cmaes>=0.10",  # exo-ilc certify --falsify: optuna's CMA-ES sampler needs it
        "clarabel>=0.9",
        "mujoco>=4",
        "myo-sim>=0.2.3,<0.3",  # MyoSuite's musculoskeletal models (MyoArm, the elbow): core/person
        "distributed>=2024.1",  # exo-ilc study --dask: cells on a Dask cluster
        "foxglove-sdk>=0.30.3,<0.31",  # exo-ilc run --live: the Foxglove WebSocket server
    ],
    extras_require={
        "test": ["pytest>=8", "hypothesis>=6.100", "pin>=3", "ruff>=0.6", "mypy>=1.10",
                 "types-PyYAML", "websockets>=12", "colcon-core", "colcon-ros",
                 "psycopg[binary]>=3.1",
                 # public URDFs (UR5, Panda) for the URDF reader's tests; the loaders pin
                 # example-robot-data 5.0.0 (tested)
                 "example-robot-data-loaders>=5", "example-robot-data>=5",
                 *DOCS_DEPENDENCIES],
        "docs": DOCS_DEPENDENCIES,
        # `exo-ilc tune --storage postgresql://...`: SQLAlchemy 2.x opens it with psycopg 3.
        "postgres": ["psycopg[binary]>=3.1"],
    },
    zip_safe=False,
    maintainer="exo_ilc_ros developers",
    maintainer_email="exo-ilc-ros@example.com",
    description="Iterative learning control (sgnPDD^2/PD over computed torque) for a "
                "rehabilitation exoskeleton arm, as ROS 2 nodes over a fast ROS-free core.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "exo-ilc = exo_ilc_ros.cli.main:main",
            *REGISTRY["console_scripts"](),
        ],
    },
)
