"""Planning helpers for the rover's decision layer.

Pure functions over the 200x200 worldmap (1 m cells, [row=y, col=x]):
occupancy and cost grids (`grid`), shortest paths (`astar`), path following
(`pursuit`), steering from the current camera frame (`reactive`), exploration
targets and loop detection (`explore`), lack-of-progress recovery (`stuck`),
the latency lead on the client's own clock (`predict`), staging points for
samples in nooks (`approach`), remembered rocks refuted by a close look (`rockmem`)
and frontiers voted wall before they were seen from close (`vanished`).
"""
