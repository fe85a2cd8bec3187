"""A job's way in, checked before anything moves (ROS-free): submit / cancel / stop and the
planning thread, the path checks (previews, the workspace box, the cell), a path made a checked
stream, the commissioned facts, the ``joint_command`` topic's commander. Imports the bus and the
motion side and ``own_thread`` only."""
