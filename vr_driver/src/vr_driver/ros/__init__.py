"""The ROS edge, the only modules that import rospy, actionlib or message packages: the driver
node (interface, trajectory_server, io_server), the nodes of the virtual devices
(virtual_controller, io_island, virtual_line), pose_terminal, status_display, check_network and
their shared helpers (support; network_check and graph_watch: the ROS graph across machines)."""
