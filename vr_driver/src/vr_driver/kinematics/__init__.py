"""The arm's geometry: solver (the URDF / KDL forward and inverse kinematics, ``Kinematics``), which
delegates to ik (the IK search), analytic (its closed form for a six-axis arm with a spherical
wrist) and limits (the joint limits); preview (the motion planner that previews a move the way
the G2 runs it, and the envelope check); scene (the cell as primitive solids) and collision (self
and world collision checks on pinocchio + coal, which kinematics.deps imports only when a checker
is built); planner (OMPL planning, with plan_search, OMPL's search, and plan_timing, TOPP-RA's
timing). Imports only the vocabulary modules (errors, poses, validate)."""
