from setuptools import setup
from catkin_pkg.python_setup import generate_distutils_setup

setup(**generate_distutils_setup(
    packages=['vr_driver', 'vr_driver.bus', 'vr_driver.protocol', 'vr_driver.kinematics', 'vr_driver.controller', 'vr_driver.driver',
              'vr_driver.driver.link', 'vr_driver.driver.motion', 'vr_driver.driver.joints', 'vr_driver.driver.checks',
              'vr_driver.driver.planning',
              'vr_driver.terminal', 'vr_driver.csr', 'vr_driver.ros', 'vr_driver.commission',
              'vr_driver.moveit'],
    package_dir={'': 'src'},
))
