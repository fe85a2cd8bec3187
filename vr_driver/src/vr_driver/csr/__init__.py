"""Offline export and import of Panasonic DTPS ``.csr`` programs. ROS-free: only the ``--from-topic``
mode of the command line (:mod:`.cli`) imports rospy, when it runs.

The format (usage, conventions and the details chosen: doc/csr.md) is plain text,
comma separated, in sections::

    [Description]   Key, value lines: Robot, Comment (<= 30 chars), SubComment1/2, Mechanism,
                    Tool, Creator (<= 16 chars), User coordinates, Create, Update, Original, Edit
    [Pose]          "/Name, Type, RT, UA, FA, RW, BW, TW" then "P001, AJ, 0.000, ..." rows
                    (AJ: joint angles in degrees; AU: X, Y, Z mm, U, V, W degrees)
    [Variable]      "LB, LB001, , 0" (type, name <= 8 chars, comment <= 32 chars, value)
    [Command]       TOOL, MOVEP, MOVEL, MOVEC lines; any other instruction is kept verbatim

One module per job; this package exports the public names of all of them:

- :mod:`.fields`: the format's constants and single-field checks; :func:`~.fields.show` quotes
  a value in a message by a short prefix.
- :mod:`.inputs`: bounded input -- file size, and YAML aliases, nesting depth and alias expansion.
- :mod:`.model`: :class:`Description`, :class:`Pose`, :class:`Variable`, :class:`Tool`,
  :class:`Move`, :class:`RawCommand`, :class:`RawSection`, :class:`CsrProgram` (frozen
  dataclasses, equal when their text is equal).
- :mod:`.writer`: :func:`format_program` / :func:`program_bytes` / :func:`write_program` (validated
  first, CsrError names the field; a file is replaced atomically, keeping its mode, and only if it
  is a regular file). :mod:`.parser`: :func:`parse_program` / :func:`read_program`
  (CsrError names the line and field). ``format_program(parse_program(text)) == text`` for every
  text the writer writes.
- :mod:`.conventions`: :class:`JointConvention` maps URDF joint angles to the AJ columns RT UA FA
  RW BW TW and back (FA relative to UA or to the horizontal, per-axis sign flips and offsets).
- :mod:`.waypoints`: :func:`load_waypoints` reads a waypoint YAML / CSV file or a YAML dump of a
  ``trajectory_msgs/JointTrajectory`` into :class:`Waypoint` records that remember their line.
- :mod:`.export`: :func:`export_program` turns waypoints into a program (Cartesian poses through
  our IK, seeded point to point; every pose inside the workspace box and every joint vector inside
  the limits, else :class:`CsrConversionError` listing each refused waypoint by its input line);
  :func:`check_program` / :func:`summarize` check and describe a program read back.
- :mod:`.cli`: the command line, ``python3 -m vr_driver.csr --help`` (also ``rosrun vr_driver
  csr_export``). Exit codes: 0 ok, 1 conversion failed (a waypoint or pose refused), 2 usage or
  input error.

Export works in controller units (mm, degrees) except joint vectors of the URDF (radians, chain
order joint_1..joint_6).
"""
from __future__ import annotations

from .cli import main
from .conventions import JointConvention
from .export import ExportSettings, check_program, export_program, kinematics_for, summarize
from .fields import CARTESIAN_COLUMNS, JOINT_COLUMNS
from .model import (Command, CsrProgram, Description, Move, Pose, RawCommand, RawSection, Tool, Variable,
                    default_variables)
from .parser import decode_csr, parse_program, read_program
from .waypoints import Waypoint, WaypointFile, load_waypoints, parse_waypoints, trajectory_waypoints
from .writer import format_program, program_bytes, write_program

__all__ = [
    "JOINT_COLUMNS",
    "CARTESIAN_COLUMNS",
    "Description",
    "Pose",
    "Variable",
    "Tool",
    "Move",
    "RawCommand",
    "RawSection",
    "Command",
    "CsrProgram",
    "default_variables",
    "format_program",
    "program_bytes",
    "write_program",
    "parse_program",
    "decode_csr",
    "read_program",
    "JointConvention",
    "Waypoint",
    "WaypointFile",
    "ExportSettings",
    "load_waypoints",
    "parse_waypoints",
    "trajectory_waypoints",
    "export_program",
    "check_program",
    "summarize",
    "kinematics_for",
    "main",
]
