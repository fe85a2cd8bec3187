"""The plan action (ROS-free): the plan core, the planning worker process (started as
``python3 -m vr_driver.driver.planning.plan_process``) and its messages. The top of the driver:
it plans for a :class:`~vr_driver.driver.core.DriverCore`, which never imports it."""
