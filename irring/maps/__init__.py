"""Stage 3, maps: the occupancy grid (mapping, with its compiled ray walk _traverse), ground
truth and scores (metrics), and pictures (render)."""
