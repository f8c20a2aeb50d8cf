"""Python package of fr5_rl, installed by catkin (catkin_python_setup)."""
from catkin_pkg.python_setup import generate_distutils_setup
from setuptools import setup

setup(**generate_distutils_setup(packages=["fr5_rl"], package_dir={"": "src"}))
