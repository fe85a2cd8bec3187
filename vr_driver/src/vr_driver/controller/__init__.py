"""The virtual G2 controller and the simulated devices, without ROS: the controller's programs
(program, session, program_v2), the simulated arms (arm, stream_arm), the virtual I/O island and
the line hub (line). Imports the vocabulary, protocol and kinematics; never the driver, the
terminal or the ROS modules."""
