"""The pose terminal without ROS: reading, checking and rounding typed poses (pose_input); the ROS
backend lives in vr_driver.ros.pose_terminal."""
