"""pyprofibus_vendor: a ROS-free PROFIBUS-DP stack (PHY, FDL, DP master class 1, DP slave, GSD)."""
