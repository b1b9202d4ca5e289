"""dexcanvas_core: the human side of dexcanvas-retarget.

Taxonomy and objects, the ``Trajectory`` schema, Lance I/O, data loaders and the RL trajectory
buffer, MANO-compatible hand kinematics. Never imports ``retarget``.
"""

__version__ = "0.1.0"
