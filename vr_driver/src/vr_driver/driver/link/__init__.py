"""The bus side of the driver core (ROS-free): the serial port and the DP master's session with the
G2 (:mod:`.link`), the card's diagnosis, the record clock, the controller's I/O stations. Imports
nothing else of the driver."""
