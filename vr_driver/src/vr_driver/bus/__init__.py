"""The PROFIBUS bus in a process of its own (ROS-free, and light: it imports only the standard
library and pyprofibus_vendor, so the bus process starts in a fraction of a second and carries no
planner, no kinematics, no ROS).

    process.py   BusProcessMaster (the driver's side: a DpMaster stand-in, the same
                 pyprofibus_vendor.master_api.MasterApi) and the bus process itself
    messages.py  what the two send each other: one typed message class each, encoded and checked
    health.py    BusHealth: the gaps between the card's Data_Exchange replies, the jitter, the
                 watchdog margin

The driver's link supervisor (vr_driver.driver.link.link) uses :class:`BusProcessMaster` in place of an
in-process :class:`~pyprofibus_vendor.dp_master.DpMaster` when ``bus_process`` is on (the node's
default): the serial port and the DP master then live in a process that does nothing but cycle the
bus, so nothing the node computes (planning, validation, collision checks, IK, ROS callbacks) can
delay a Data_Exchange past the card's watchdog.
"""
