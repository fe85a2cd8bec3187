"""The arm's joints as the driver knows them (ROS-free): what each record says of them (tracking,
the wire's resolution, the model check) and how closely the arm follows a plan (supervision,
``feedback_states``). Imports the bus and the motion side only."""
