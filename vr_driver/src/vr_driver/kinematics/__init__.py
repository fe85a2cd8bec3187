"""The arm's geometry: solver (the URDF / KDL forward and inverse kinematics) and preview (the
motion planner that previews a move the way the G2 runs it, and the envelope check). Imports only
the vocabulary modules (errors, poses, validate)."""
