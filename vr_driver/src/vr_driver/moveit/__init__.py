"""What MoveIt 1 needs to plan what the driver accepts, made from the stack's own files, without ROS
(doc/moveit.md): the cell as MoveIt's ``.scene`` text with the driver's padding (:mod:`.scene_text`),
the SRDF, controller list and joint limits for a prefixed robot or a commissioned G2
(:mod:`.config`), the OPW parameters of the model (:mod:`.opw`), and the command line that prints
them for a launch file (:mod:`.cli`: ``rosrun vr_driver moveit_config``). Imports the vocabulary and
``kinematics.scene`` only."""
