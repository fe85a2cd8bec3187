"""Commissioning: the G2's unknowns measured from the bus (``rosrun vr_driver commission``,
doc/commissioning.md). ROS-free.

- :mod:`.bus`: the driver's link supervisor on the serial port, one DP cycle per call, every cycle
  logged; :func:`~.bus.port_users` (who else holds the port).
- :mod:`.analysis`: the numbers from the logged records (loop period, cruise speed, ramp fits).
- :mod:`.steps`: the steps, each an assumption of protocol v3 (doc/controller_program.md §10.9)
  measured, with its verdict and consequence.
- :mod:`.report`: the table and the files (the YAML for ``driver.launch commissioning:=FILE``, a
  MoveIt ``joint_limits.yaml``).
- :mod:`.cli`: the command line (``python3 -m vr_driver.commission``).
"""
