"""The arm's geometry: solver (the URDF / KDL forward and inverse kinematics) and preview (the
motion planner that previews a move the way the G2 runs it, and the envelope check); scene (the
cell as primitive solids) and collision (self and world collision checks on pinocchio + coal, which
kinematics.deps imports only when a checker is built). Imports only the vocabulary modules (errors,
poses, validate)."""
