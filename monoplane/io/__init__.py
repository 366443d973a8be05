"""Reading inputs: frames, point clouds, and the file checks behind their one-line errors."""
