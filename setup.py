from catkin_pkg.python_setup import generate_distutils_setup
from setuptools import setup

setup(**generate_distutils_setup(packages=["grid_puzzle_localization", "grid_puzzle_localization.pcd", "grid_puzzle_localization.ros", "grid_puzzle_localization.tiling"], package_dir={"": "src"}))
setup(**generate_distutils_setup(packages=["grid_puzzle_localization", "grid_puzzle_localization.pcd", "grid_puzzle_localization.ros", "grid_puzzle_localization.sim"], package_dir={"": "src"}))
setup(**generate_distutils_setup(packages=["grid_puzzle_localization", "grid_puzzle_localization.blocks", "grid_puzzle_localization.pcd", "grid_puzzle_localization.ros"], package_dir={"": "src"}))
setup(
    **generate_distutils_setup(
        packages=[
            "grid_puzzle_localization",
            "grid_puzzle_localization.evaluation",
            "grid_puzzle_localization.experiment",
            "grid_puzzle_localization.monitor",
            "grid_puzzle_localization.pcd",
            "grid_puzzle_localization.report",
            "grid_puzzle_localization.ros",
        ],
        package_dir={"": "src"},
    )
)
