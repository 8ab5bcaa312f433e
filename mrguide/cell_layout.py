"""The cell's layout, the same in every engine and drawing of it: the table and the suction cup (robot base frame, m)."""

#: Radius of the suction cup's lip.
CUP_RADIUS = 0.02
#: The table: a box whose top face is at z = 0.
TABLE_CENTER = (0.45, 0.10, -0.02)
TABLE_HALF_EXTENTS = (0.55, 0.60, 0.02)
