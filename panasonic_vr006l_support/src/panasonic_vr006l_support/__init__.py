"""Python helpers of the VR-006L support package: render the xacro, read the model, draw it (ROS-free)."""
