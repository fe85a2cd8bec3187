"""The motion side of the driver core (ROS-free): jobs and their outcomes, the sequencers that
turn a job into the records to send (handshake, stream), the stream's points, the snapshot the
driver publishes. Imports the bus side (``link``) only."""
