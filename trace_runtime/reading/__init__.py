"""Reading: one segment's cycles in any tier (``reader``), the sensor recordings evidence
points into (``recordings``), a log of many files and copies (``logset``), a hot segment
followed while it is written (``growing_file``), and each robot's Merkle tree read from its
files (``chain_tree``).
"""
