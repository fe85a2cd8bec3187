from setuptools import setup
from catkin_pkg.python_setup import generate_distutils_setup

setup(**generate_distutils_setup(
    packages=['vr_driver', 'vr_driver.driver', 'vr_driver.csr'],
    package_dir={'': 'src'},
))
