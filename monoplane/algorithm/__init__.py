"""The algorithm of the paper: sequential RANSAC, graph cut, max-flow, dense CRF, regions,
planarity."""
