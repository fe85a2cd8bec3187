from setuptools import setup
from catkin_pkg.python_setup import generate_distutils_setup

setup(**generate_distutils_setup(
    packages=['panasonic_vr006l_support'],
    package_dir={'': 'src'},
))
