"""Planning helpers for the rover's decision layer.

Pure functions over the 200x200 worldmap (1 m cells, [row=y, col=x]):
occupancy and cost grids (`grid`), shortest paths (`astar`), path following
(`pursuit`), steering from the current camera frame (`reactive`), exploration
targets and loop detection (`explore`), lack-of-progress recovery (`stuck`),
the latency lead on the client's own clock (`predict`), staging points for
samples in nooks (`approach`), remembered rocks refuted by a close look (`rockmem`)
and frontiers voted wall before they were seen from close (`vanished`).

Beside them, the decision layer's planning glue, which works on the rover and its
`rover.nav` memory rather than on plain arrays: the frontier goal (`exploration_plan`),
the sample search's goals (`search_plan`), the rock to approach (`rock_choice`) and the
maps planned on plus the path kept in `nav` (`paths`). They never import `decision`.
"""
